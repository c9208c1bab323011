"""
The Hadamard check of the term selection: a rate random walk K or a rate ramp R.

Over the last decade of the Allan curve a random walk (K^2 tau / 3) and a ramp (R^2 tau^2 / 2)
differ little, and the fit often leaves both term sets open.  The overlapping Hadamard variance
cancels a constant rate slope (a ramp adds nothing), while a random walk adds K^2 tau / 6
(:func:`~imu_allan.core.terms.hadamard_shape`).  Per open term set, when they differ in K, on
the OHVAR curve (:class:`HadamardProblem`) with the set's Q / N / B terms:

* a set without K is contradicted when adding K gains more than :data:`MARGIN` in the
  selection criterion;
* a set with K is contradicted when the lower end of the 95 % interval of the K^2 its Allan fit
  needs exceeds the upper end of K^2's 95 % interval on the Hadamard curve.

A contradicted selection is replaced by the best open set not contradicted; if every open set
is, the curves disagree and nothing is decided.  Opt-in (the OHDEV curve given); method and
measurements: docs/method.md section 4.
"""

import math

import numpy as np

from .axis import (
    ALTERNATIVE_MARGIN,
    coefficient_interval,
    fit_terms,
    Problem,
    selection_penalty,
    shape_columns,
    two_sided_z,
)
from .tau_range import TauRange
from ..allan.edf import edf_greenhall
from ..terms import hadamard_shape, ID_ALPHA

#: Criterion gain of K on the Hadamard curve that contradicts a term set without K.
MARGIN = 10.0
#: Name of the curve in the fit's evidence (the deviation kind, as report.json names it).
CURVE = 'ohdev'
_WALK = 'rate_random_walk'
_BASE = ('quantization', 'white_noise', 'bias_instability')
#: Two-sided level of the intervals compared (95 %: each side 2.5 %).
LEVEL = 0.95
#: Averaging times with fewer non-overlapping clusters are left out (as the Allan grid does).
MIN_CLUSTERS = 10


class HadamardProblem(Problem):
    """
    A :class:`~imu_allan.core.fit.Problem` on an OHVAR curve: Hadamard shapes and widths.

    The OHVAR estimates correlate over narrower spans of log tau than the OAVAR ones (widths
    measured as the Allan ones were, docs/method.md section 4); flicker keeps the Allan
    long-range share (0.08 +- 0.05 measured at two decades).
    """

    correlation_widths = {2: 0.30, 1: 0.30, 0: 0.30, -1: 0.34, -2: 0.38}

    def column(self, name, position=None):
        """OHVAR shape of an IEEE term at the averaging times (cached)."""
        if name not in self._columns:
            self._columns[name] = hadamard_shape(name, self.tau, self.rate_hz)
        return self._columns[name]


def hadamard_problem(ohdev, axis, coef=None, tau_min=None):
    """
    Build the OHVAR problem of ``axis`` from an ``ohdev`` DeviationResult (None: too short).

    ``tau_min`` (s): the Allan fit's shortest averaging time.  With ``coef`` (the selected
    Allan fit's squared coefficients) the noise at each averaging time is the term dominating
    the predicted Hadamard curve, and the EDF Greenhall & Riley's for it (d = 3, F = S = m),
    not the curve's own identification (unreliable at the longest taus, docs/method.md 4).
    """
    j = ohdev.axis_index(axis)
    edf, alpha = ohdev.edf[:, j], ohdev.alpha[:, j]
    tau = np.asarray(ohdev.tau, float)
    shaped = {n: c * hadamard_shape(n, tau, ohdev.rate_hz)
              for n, c in (coef or {}).items() if n != 'rate_ramp'}
    if shaped:
        names = list(shaped)
        dominant = np.argmax(np.column_stack([shaped[n] for n in names]), axis=1)
        alpha = np.array([ID_ALPHA[names[k]] for k in dominant])
        edf = np.array([edf_greenhall(int(a), 3, int(m), ohdev.n_samples + 1, True, False)
                        for a, m in zip(alpha, ohdev.m)])
    edf = np.where(ohdev.m * MIN_CLUSTERS <= ohdev.n_samples, edf, np.nan)
    problem = HadamardProblem(tau, ohdev.dev[:, j] ** 2, edf, alpha, ohdev.rate_hz,
                              span=None if tau_min is None else TauRange(tau_min, math.inf))
    return problem if problem.tau.size >= 4 else None


def applies(fit):
    """
    Return whether the check can judge an Allan fit: IEEE terms only, no fitted line.

    The Hadamard shapes are the IEEE terms' (:func:`~imu_allan.core.terms.hadamard_shape`); a
    sinusoid, a line or a Gauss-Markov bends the OHVAR curve in ways its fit cannot follow,
    so K against R is then left to the Allan fit (its alternatives stay open).
    """
    return set(fit.coef) <= set(ID_ALPHA) and not fit.lines


def open_sets(candidates, margin=ALTERNATIVE_MARGIN):
    """Return the term sets (tuples) within ``margin`` of the best criterion, best first."""
    if not candidates:
        return []
    best = candidates[0][0]
    return [tuple(names) for crit, names in candidates if crit - best < margin]


def _walk(fit, level):
    """Return ``(c, lo, hi)``: a fit's squared walk coefficient and its ``level`` bounds."""
    if _WALK not in fit.coef:
        return 0.0, 0.0, 0.0
    j = list(fit.coef).index(_WALK)
    lo, hi = coefficient_interval(fit.coef[_WALK], max(fit.cov[j, j], 0.0), level)
    return fit.coef[_WALK], lo * lo, hi * hi


def hadamard_walk(hadamard, names):
    """
    Say what the OHVAR curve says about K beside the Q / N / B terms of ``names``.

    Returns ``(gain, upper)``: the criterion gain of adding K (chi^2 drop minus the
    selection penalty, as :func:`~imu_allan.core.fit.fit_axis` scores term sets) and the
    upper end of K^2's 95 % interval (the unconstrained GLS sd where the fit pins K at 0).
    """
    # white noise and flicker always: the OHVAR curve sees a flicker floor the Allan set may
    # not hold (a weak one beside a ramp), and K fitted without it takes the floor for a walk
    base = [n for n in _BASE if n in names or n != 'quantization']
    without = fit_terms(hadamard, base, profile_intervals=False)
    with_k = fit_terms(hadamard, base + [_WALK], profile_intervals=False)
    gain = without.chi2 - with_k.chi2 - (selection_penalty(hadamard) if _WALK in with_k.coef
                                         else 0.0)
    c, _, hi = _walk(with_k, LEVEL)
    if c == 0.0:
        coef, _, g = hadamard.solve(shape_columns(hadamard, base + [_WALK], {}))
        sd = math.sqrt(max(float(np.linalg.pinv(g.T @ g)[-1, -1]), 0.0))
        hi = two_sided_z(LEVEL) * sd
    return gain, hi


def check(allan, hadamard, candidates, margin=ALTERNATIVE_MARGIN):
    """
    Return the evidence of the Hadamard curve on the open term sets, best first.

    ``allan``, ``hadamard``: the axis' :class:`Problem` and :class:`HadamardProblem`;
    ``candidates``: ``(criterion, names)`` of the Allan selection, best first.  Each entry:
    ``terms`` (list), ``curve`` ('ohdev'), ``gain`` (criterion gain of K on the Hadamard
    curve), ``walk_min`` (the lower end of the 95 % interval of the K^2 the set's Allan fit
    needs, 0 without K), ``walk_max`` (the upper end of K^2's 95 % interval on the Hadamard
    curve) and ``rejected``.  Empty when the open sets agree on K.
    """
    sets = open_sets(candidates, margin)
    if len(sets) < 2 or len({_WALK in s for s in sets}) < 2:
        return []
    out = []
    for names in sets:
        gain, walk_max = hadamard_walk(hadamard, names)
        _, walk_min, _ = _walk(fit_terms(allan, names, profile_intervals=False), LEVEL)
        if _WALK in names:
            rejected = walk_min > walk_max
        else:
            rejected = gain > MARGIN
        out.append({'terms': list(names), 'curve': CURVE, 'gain': float(gain),
                    'walk_min': float(walk_min), 'walk_max': float(walk_max),
                    'rejected': bool(rejected)})
    if all(e['rejected'] for e in out):  # the curves disagree on every open set: no decision
        for e in out:
            e['rejected'] = False
    return out


def decide(fit, allan, hadamard, margin=ALTERNATIVE_MARGIN):
    """
    Apply the Hadamard check to an automatic :class:`AxisFit`; return the (new) AxisFit.

    The evidence is kept as ``fit.evidence``.  A selection the Hadamard curve contradicts is
    replaced by the best open set (by the Allan criterion) it does not contradict, refitted
    with intervals.
    """
    evidence = check(allan, hadamard, fit.candidates, margin)
    if not evidence:
        return fit
    kept = [e for e in evidence if not e['rejected']]  # never empty (see check)
    if set(kept[0]['terms']) != set(fit.terms):
        new = fit_terms(allan, kept[0]['terms'])
        new.candidates = fit.candidates
        new.candidate_fits = fit.candidate_fits
        new.selection_penalty = fit.selection_penalty
        fit = new
    fit.evidence = evidence
    return fit
