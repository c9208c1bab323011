"""
The Hadamard check of the term selection: a rate random walk K or a rate ramp R.

On the Allan curve a random walk (AVAR K^2 tau / 3) and a ramp (R^2 tau^2 / 2) both rise at the
longest averaging times, where the estimates have few degrees of freedom: over the last decade
or so the two shapes differ little, and the Allan fit often leaves both term sets open
(:meth:`~imu_allan.core.fit.FittedModel.alternatives`).  The overlapping Hadamard variance
(third differences of the phase, SP1065 eq 20) cancels a constant rate slope exactly, so a
ramp adds nothing to it, while a random walk adds K^2 tau / 6
(:func:`~imu_allan.core.terms.hadamard_shape`).

Test, per open term set S (criterion within the alternatives' margin) when the open sets
differ in K: the Allan fit of S predicts the OHVAR curve (each term's squared coefficient times
its Hadamard shape; a ramp adds nothing).  The measured OHVAR is Gaussian about it with the
covariance S C S of :class:`~imu_allan.core.fit.Problem` (chi-square variances 2 h^2 / EDF of
the predicted curve h with the OHDEV EDF of Greenhall & Riley, the correlation C between
averaging times of :mod:`.fit`), so its deviance is D = r^T r + 2 sum ln h (r the whitened
residual; the log-determinant matters, since the candidates' predicted curves, and with them
the variances, differ: without it a prediction too high everywhere scores best).  A set is
contradicted when its D exceeds the smallest over the open sets by more than
:data:`MARGIN` (10, "very strong" on the scale of Kass & Raftery 1995, as the advisor's
separation margin) and it differs from that best set in K.

A contradicted set leaves the alternatives; a contradicted selection is replaced by the best
(by the Allan criterion) open set the Hadamard curve does not contradict; the set with the
smallest deviance is never contradicted.
"""

import numpy as np

from .deviations.greenhall import edf_greenhall
from .fit import ALTERNATIVE_MARGIN, fit_terms, Problem
from .terms import hadamard_shape, ID_ALPHA

#: Deviance above the best open set's at which the Hadamard curve contradicts a term set.
MARGIN = 10.0
#: Name of the curve in the fit's evidence (the deviation kind, as report.json names it).
CURVE = 'ohdev'
_WALK = 'rate_random_walk'
#: Averaging times with fewer non-overlapping clusters are left out (as the Allan grid does).
MIN_CLUSTERS = 10


class HadamardProblem(Problem):
    """A :class:`~imu_allan.core.fit.Problem` on an OHVAR curve: Hadamard shapes per term."""

    def column(self, name, position=None):
        """OHVAR shape of an IEEE term at the averaging times (cached)."""
        if name not in self._columns:
            self._columns[name] = hadamard_shape(name, self.tau, self.rate_hz)
        return self._columns[name]


def hadamard_problem(ohdev, axis, coef=None):
    """
    Build the OHVAR problem of ``axis`` from an ``ohdev`` DeviationResult (None: too short).

    With ``coef`` (the selected Allan fit's squared coefficients) the noise at each averaging
    time is the term that dominates the predicted Hadamard curve, as the Allan side
    identifies it on the fitted model (:func:`~imu_allan.core.allan.identify_noise`), and the
    OHDEV EDF is Greenhall & Riley's for that noise (d = 3, F = S = m).  The per-tau
    identification of the curve itself (lag-1 ACF, B1 below 30 block means) is not used: at
    the longest taus, from a handful of blocks, it returns white or flicker PM now and then
    (alpha = 2: an EDF of 1e5 for one point of a flicker curve, which then decides the fit).
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
    problem = HadamardProblem(tau, ohdev.dev[:, j] ** 2, edf, alpha, ohdev.rate_hz)
    return problem if problem.tau.size >= 4 else None


def deviance(hadamard, fit):
    """
    Deviance of the OHVAR curve about the curve the Allan ``fit`` predicts (no refit).

    r^T r + 2 sum ln h: the Gaussian -2 ln L up to a constant common to every prediction, with
    the covariance :meth:`Problem.whiten` uses (h floored at 1e-3 of the measured curve, as
    there).
    """
    pred = np.zeros(hadamard.tau.size)
    for name, c in fit.coef.items():
        pred = pred + c * hadamard.column(name)
    noise = np.maximum(pred, 1e-3 * hadamard.avar)
    resid = hadamard.whiten(noise, (hadamard.avar - pred)[:, None])[:, 0]
    return float(resid @ resid + 2.0 * np.sum(np.log(noise)))


def open_sets(candidates, margin=ALTERNATIVE_MARGIN):
    """Term sets (tuples) whose criterion is within ``margin`` of the best, best first."""
    if not candidates:
        return []
    best = candidates[0][0]
    return [tuple(names) for crit, names in candidates if crit - best < margin]


def check(allan, hadamard, candidates, margin=ALTERNATIVE_MARGIN):
    """
    Evidence of the Hadamard curve on the open term sets: a list of dicts, best first.

    ``allan``, ``hadamard``: the axis' :class:`Problem` and :class:`HadamardProblem`;
    ``candidates``: ``(criterion, names)`` of the Allan selection, best first.  Each entry:
    ``terms`` (list), ``curve`` ('ohdev'), ``deviance`` (above the smallest of the open sets)
    and ``rejected``.  Empty when the open sets agree on K (nothing for the curve to decide).
    """
    sets = open_sets(candidates, margin)
    if len(sets) < 2 or len({_WALK in s for s in sets}) < 2:
        return []
    dev = [deviance(hadamard, fit_terms(allan, names, profile_intervals=False))
           for names in sets]
    best = sets[int(np.argmin(dev))]
    return [{'terms': list(names), 'curve': CURVE, 'deviance': float(d - min(dev)),
             'rejected': bool(d - min(dev) > MARGIN and (_WALK in names) != (_WALK in best))}
            for names, d in zip(sets, dev)]


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
    kept = [e for e in evidence if not e['rejected']]  # never empty: the best D stays
    if set(kept[0]['terms']) != set(fit.terms):
        new = fit_terms(allan, kept[0]['terms'])
        new.candidates = fit.candidates
        fit = new
    fit.evidence = evidence
    return fit
