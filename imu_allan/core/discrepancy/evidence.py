"""
What one recording says about each term of a stated (intended) noise model.

Per axis (:class:`AxisEvidence`) the stated terms are refitted with their amplitudes free and
their positions held as stated, in the gap's own metric (:meth:`.band.Band.problem`); each
amplitude / stated is a *factor* with a log-space standard error from the sandwich covariance.
Around that: absent terms with upper limits, a freed Gauss-Markov tau_c, a stated walk tried as
a bounded Gauss-Markov, up to :data:`MAX_MISSING` effects the model lacks
(:func:`.workflow.evaluate_candidates`), zeroed terms, and the raw numbers the run-to-run,
drive and metadata evidence need.  docs/discrepancy.md section 8 ("One recording's evidence")
describes each step.  SI units throughout; factors are measured / stated.  ROS-free.
"""

from dataclasses import dataclass, field
import math
from typing import NamedTuple

import numpy as np

from .band import ALPHA, effective_count, measure_gap, model_band
from .significance import improvement_test, satterthwaite
from .workflow import evaluate_candidates, two_pass_fit
from ..allan.estimate import allan_deviation
from ..fit import fit_terms
from ..simulation.gauss_markov import driving_density, stationary_sigma
from ..terms import TERMS

#: Share of the record whose mean stands for the turn-on bias (first tenth) and for the end.
SEGMENT = 0.1
#: Most effects added per axis to the refitted model of one recording.
MAX_MISSING = 2
#: A stated term is 'not needed' when dropping it raises Q with a p-value above this: the data
#: then say nothing about its size but an upper limit, and no factor is measured.
NOT_NEEDED_P = 0.05
#: A stated term's factor is measured only where the data need it clearly (dropping it has a
#: p-value below this): a barely visible amplitude has a skewed, ill-determined log, and
#: keeping the recordings where it happened to show would bias the pooled factor upwards.
NEEDED_P = 1e-3
#: Upper limits of an unneeded term are computed when its stated size has a p-value below this.
REJECTED_P = 0.01
#: A freed correlation time is held at its fitted value, before effects the model lacks are
#: looked for, when freeing it improves the fit with a p-value below this.
ADOPT_P = 0.01
#: The sandwich error of a fitted amplitude's log is a little small: over 80 records of white
#: noise alone (40 of 75 000 samples at 250 Hz, 40 of 360 000 at 100 Hz) the factor's z had
#: an rms of 1.10 (sd 1.04-1.09, mean -0.15 to -0.36).  Widened by this factor.
AMPLITUDE_SE_INFLATION = 1.1
#: The sandwich error of a freed correlation time (and of the amplitude fitted with it) is too
#: small: over 12 simulated 3 h records of PX4's gyro bias (tau_c 300 s, hump near the end of
#: the span) ln tau_c scattered by 0.34 where the sandwich said 0.24.  Widened by this factor.
POSITION_SE_INFLATION = 1.5
#: A freed correlation time counts as measured when its log has a standard error below this
#: (the bend is resolved within +-65 %).
MAX_POSITION_SE = 0.5
#: The freed correlation time of a stated Gauss-Markov ranges over
#: [tau_0 / peak ratio, WIDE_FACTOR * tau_max]: a hump anywhere in the span, or no bend at all.
WIDE_FACTOR = 100.0


@dataclass
class Recording:
    """
    One recording of the simulator (or sensor) configuration under test.

    ``data`` (n, A) SI samples, ``rate_hz`` their rate, ``axes`` the column names, ``source``
    a name for the report, ``stated_variance`` the per-sample variance per axis that the
    recording's message metadata state (Imu covariance diagonals; None when unknown).
    ``measured`` is the Allan deviation of exactly these data, rate and axes on the analysis's
    averaging-time grid, when already computed (e.g. ``DiscrepancyResult.measured`` with the
    same ``points_per_decade`` and ``min_clusters``); None: :func:`measure_recording`
    computes it.
    """

    data: np.ndarray
    rate_hz: float
    axes: tuple
    source: str = ''
    stated_variance: dict = None
    measured: object = None

    @property
    def duration_s(self):
        """Length of the record, s."""
        return self.data.shape[0] / self.rate_hz


@dataclass
class LogEstimate:
    """ln(measured / stated) of one quantity in one recording, with its standard error."""

    log: float
    se: float
    rate_hz: float

    @property
    def usable(self):
        """Return True when the estimate carries information (finite, positive error)."""
        return math.isfinite(self.log) and math.isfinite(self.se) and self.se > 0


@dataclass
class AxisEvidence:
    """
    One axis of one recording against its stated terms (see the module docstring).

    ``scales[term]`` and ``positions[term]`` are :class:`LogEstimate` (amplitude and position
    factors), ``free_scales`` the amplitude factors with the positions free, ``absent[term]``
    the factor's upper limits ``{'upper68', 'upper_crit', 'p_stated'}``, ``process`` the
    wrong-process evidence or None, ``missing`` the effects added (``{'term', 'params',
    'p_value'}``), ``gap_stated`` / ``gap_fitted`` the gap against the stated and the
    refitted model, ``means`` / ``slope_per_s`` / ``rms`` the raw statistics, ``white_variance``
    the per-sample white variance with its EDF, ``zeroed`` the stated terms of amplitude zero
    (``{term: params}``, left out of ``stated`` and of the fit), ``tau_range`` the averaging
    times measured (s).
    """

    axis: str
    rate_hz: float
    duration_s: float
    stated: dict
    fitted: dict
    scales: dict = field(default_factory=dict)
    free_scales: dict = field(default_factory=dict)
    positions: dict = field(default_factory=dict)
    position_p: dict = field(default_factory=dict)
    absent: dict = field(default_factory=dict)
    process: dict = None
    missing: list = field(default_factory=list)
    gap_stated: float = math.nan
    gap_fitted: float = math.nan
    consistent_fitted: bool = True
    means: dict = field(default_factory=dict)
    mean_noise_var: dict = field(default_factory=dict)
    slope_per_s: float = math.nan
    rms: float = math.nan
    white_variance: tuple = (math.nan, math.nan)
    stated_variance: float = None
    zeroed: dict = field(default_factory=dict)
    tau_range: tuple = (math.nan, math.nan)


class _Axis(NamedTuple):
    """One measured axis: ln(adev) ``y`` of column ``j`` of ``measured``, at ``rate`` Hz."""

    y: np.ndarray
    measured: object
    j: int
    rate: float

    def fit(self, names, init=None, fixed=None, ranges=None):
        """Return :func:`.workflow.two_pass_fit` of ``names`` here: ``(problem, fit)``."""
        return two_pass_fit(self.y, self.measured, self.j, names, init, fixed, ranges)


def _log_sd(fit, term, kind):
    """Return the standard error of a fitted log parameter (``kind`` 'amp', 'pos'), or inf."""
    i = fit.labels.index((term, kind))
    v = fit.log_cov[i, i]
    return math.sqrt(v) if np.isfinite(v) and v > 0 else math.inf


def amplitude(params, term):
    """Return the amplitude of one term's parameters (its first one: N, B, K, sigma ...)."""
    return TERMS[term].unpack(params)[0]


def _positions(terms):
    return {t: TERMS[t].unpack(p)[1] for t, p in terms.items() if TERMS[t].position}


def _drop_test(prob, fit, names, term, fixed):
    """p-value of dropping ``term`` (the others refitted): large when the data do not need it."""
    rest = [t for t in names if t != term]
    if not rest:
        return 0.0
    without = fit_terms(prob, rest, init=fit.terms,
                        fixed={t: p for t, p in fixed.items() if t != term})
    cols = [i for i, (t, _) in enumerate(fit.labels) if t == term]
    others = [i for i, (t, _) in enumerate(fit.labels) if t != term]
    p, _ = improvement_test(without.chi2 - fit.chi2, fit.jac[:, others], fit.jac[:, cols],
                            prob.corr)
    return p


def _q_with_fixed(prob, names, term, amp, fit, fixed):
    """Q of the fit with ``term``'s amplitude held at ``amp`` (the others refitted)."""
    spec = TERMS[term]
    held = spec.pack(amp, fixed.get(term))
    offset = np.maximum(spec.avar(held, prob.tau, prob.rate_hz), 0.0)
    # never empty: a lone term is needed (_drop_test gives it p = 0), so it is never absent
    rest = [t for t in names if t != term]
    sub = prob.with_offset(offset)
    refit = fit_terms(sub, rest, init=fit.terms,
                      fixed={t: p for t, p in fixed.items() if t != term})
    return refit.chi2


def _absent(prob, fit, names, term, fixed, stated_amp, z_crit):
    """
    Return the p-value of an unneeded term's stated size and, if rejected, upper limits.

    A change of Q by c z^2 (c: :func:`_q_scale`) is a z-sigma move of the term's amplitude:
    the 68.3 % and ``z_crit`` upper limits of its factor (of the stated amplitude) are where Q
    has grown by c and c z_crit^2 (the other terms refitted each time).
    """
    from scipy.stats import norm

    def q_at(amp):
        return _q_with_fixed(prob, names, term, amp, fit, fixed)

    def upper(q_target):  # the largest factor whose Q stays below q_target
        if q_stated <= q_target:
            return 1.0
        lo = math.log(max(amplitude(fit.terms[term], term), stated_amp * 1e-6))
        hi = math.log(stated_amp)
        for _ in range(18):  # bisection in log amplitude: 18 halvings of a <= 14-e-fold span
            mid = 0.5 * (lo + hi)
            if q_at(math.exp(mid)) <= q_target:
                lo = mid
            else:
                hi = mid
        return math.exp(lo) / stated_amp
    scale = _q_scale(prob, fit, term)
    q_stated = q_at(stated_amp)
    p_stated = float(2.0 * norm.sf(math.sqrt(max(q_stated - fit.chi2, 0.0) / scale)))
    out = {'p_stated': p_stated, 'upper68': 1.0, 'upper_crit': 1.0}
    if p_stated < REJECTED_P:  # the stated size does not fit: how large could it be?
        out['upper68'] = upper(fit.chi2 + scale)
        out['upper_crit'] = upper(fit.chi2 + scale * z_crit ** 2)
    return out


def _q_scale(prob, fit, term):
    """
    Satterthwaite scale c of a one-parameter drop in Q under the correlated null.

    A change of Q by c z^2 is a z-sigma change of that parameter (c = tr(PRPR) / tr(PR) for
    the projection P on its Jacobian column; 1 for independent averaging times).
    """
    i = fit.labels.index((term, 'amp'))
    others = [k for k in range(fit.jac.shape[1]) if k != i]
    match = satterthwaite(fit.jac[:, others], fit.jac[:, [i]], prob.corr)
    return 1.0 if match is None else match[0]


def _position_p(prob, free, names, fit, fixed):
    """
    p-value of a Gauss-Markov's freed tau_c, with the look-elsewhere factor T_eff.

    ``free`` (the Gauss-Markov's tau_c free) is compared with ``names`` refitted on ``prob``
    from ``fit`` with the positions ``fixed``.  The freed position was searched over the whole
    span, where about T_eff distinguishable places exist: as for a hump candidate
    (:func:`.workflow.evaluate_candidates`) the Satterthwaite p-value is multiplied by T_eff.
    """
    pos = [free.labels.index(('gauss_markov', 'pos'))]
    rest = [i for i in range(free.jac.shape[1]) if i not in pos]
    q_fixed = fit_terms(prob, names, init=fit.terms, fixed=fixed).chi2
    p, _ = improvement_test(q_fixed - free.chi2, free.jac[:, rest], free.jac[:, pos], prob.corr)
    return min(1.0, p * max(effective_count(prob.corr), 1.0))


def _log_drive(fit):
    """
    Return ln(driving density) of the fit's Gauss-Markov (tau_c free) and its standard error.

    The driving density sigma sqrt(2 / tau_c) is what a walk and a Gauss-Markov share below
    tau_c: ln sigma - ln tau_c / 2 + const, its variance from the two logs' covariance.
    """
    sigma, tau_c = TERMS['gauss_markov'].unpack(fit.terms['gauss_markov'])
    if not sigma > 0:  # pinned at zero: no density to measure
        return math.nan, math.inf
    i, k = fit.labels.index(('gauss_markov', 'amp')), fit.labels.index(('gauss_markov', 'pos'))
    c = fit.log_cov
    var = c[i, i] + 0.25 * c[k, k] - c[i, k]
    se = math.sqrt(var) if np.isfinite(var) and var > 0 else math.inf
    return math.log(driving_density(sigma, tau_c)), se


def _wide(measured):
    """Range of a freed Gauss-Markov tau_c: a peak anywhere in the span, or no bend at all."""
    return {'gauss_markov': (float(measured.tau[0]) / TERMS['gauss_markov'].peak_ratio,
                             WIDE_FACTOR * float(measured.tau[-1]))}


def _free_position(ax, names, fit, fixed):
    """Fit the stated Gauss-Markov with its tau_c free; return the fit and the p-value."""
    others = {t: p for t, p in fixed.items() if t != 'gauss_markov'}
    prob, free = ax.fit(names, fit.terms, others, _wide(ax.measured))
    return free, _position_p(prob, free, names, fit, fixed)


def _bounded_walk(ax, names, fit, fixed):
    """
    Try a stated random walk as a Gauss-Markov with its tau_c free.

    Returns ``(process evidence, the fit with the Gauss-Markov in its place)`` when that fit
    bends inside the span (its hump's peak before the longest averaging time), else
    ``(None, None)``.  The evidence's p-value is that of the position (a walk is the
    Gauss-Markov's tau_c -> inf limit), with the look-elsewhere factor.
    """
    t_max = float(ax.measured.tau[-1])
    alt = [t for t in names if t != 'rate_random_walk'] + ['gauss_markov']
    k_stated = fit.terms['rate_random_walk']['value']
    init = {t: fit.terms[t] for t in alt if t in fit.terms}
    init['gauss_markov'] = {'sigma': stationary_sigma(k_stated, t_max), 'tau_c': t_max}
    prob, bounded = ax.fit(alt, init, fixed, _wide(ax.measured))
    p = _position_p(prob, bounded, names, fit, fixed)
    tau_fit = bounded.terms['gauss_markov']['tau_c']
    if bounded.at_bound['gauss_markov']['tau_c'] or \
            tau_fit * TERMS['gauss_markov'].peak_ratio >= t_max:
        return None, None
    log_k, se_k = _log_drive(bounded)
    return {'term': 'rate_random_walk', 'kind': 'bounded', 'p_value': p,
            'estimate': LogEstimate(log_k, se_k, ax.rate), 'tau_c_fit': tau_fit}, bounded


def _gauss_markov_tests(ev, ax, names, fit, fixed, freed=None):
    """
    Fill the position factors of ``ev``'s stated Gauss-Markov and the wrong-process evidence.

    The process is a walk where the Gauss-Markov is stated.  ``freed`` is the (free fit,
    p-value) of :func:`_free_position` when already made with these terms.
    """
    t_max = float(ax.measured.tau[-1])
    stated = ev.stated['gauss_markov']
    free, p = freed or _free_position(ax, names, fit, fixed)
    tau_fit = free.terms['gauss_markov']['tau_c']
    se = _log_sd(free, 'gauss_markov', 'pos') * POSITION_SE_INFLATION
    ev.position_p['gauss_markov'] = p
    # only a resolved bend is a measurement: an unresolved tau_c wanders along the
    # sigma-tau_c ridge of a hump seen from one side, and such estimates are biased (the
    # decision itself is the position test's p-value, combined over the recordings)
    if not free.at_bound['gauss_markov']['tau_c'] and se < MAX_POSITION_SE:
        ev.positions['gauss_markov'] = LogEstimate(math.log(tau_fit / stated['tau_c']), se,
                                                   ax.rate)
        ev.free_scales['gauss_markov'] = LogEstimate(
            math.log(amplitude(free.terms['gauss_markov'], 'gauss_markov')
                     / amplitude(stated, 'gauss_markov')),
            _log_sd(free, 'gauss_markov', 'amp') * POSITION_SE_INFLATION, ax.rate)
    # the data keep rising where the stated Gauss-Markov would have levelled off
    if ev.process is None and tau_fit > t_max and \
            TERMS['gauss_markov'].peak_ratio * stated['tau_c'] < 0.5 * t_max:
        log_k, se_k = _log_drive(free)
        ev.process = {'term': 'gauss_markov', 'kind': 'walk', 'p_value': p,
                      'estimate': LogEstimate(log_k - math.log(driving_density(
                          stated['sigma'], stated['tau_c'])), se_k, ax.rate),
                      'tau_c_fit': tau_fit}


def split_zeroed(terms):
    """Return ``(terms with a positive amplitude, the terms whose amplitude is 0)``."""
    kept = {t: p for t, p in terms.items() if amplitude(p, t) > 0}
    return kept, {t: p for t, p in terms.items() if t not in kept}


def _raw_statistics(x, rate_hz):
    """Means of the first and last tenth of the record, and the LS slope (per s)."""
    n = x.size
    k = max(1, int(round(SEGMENT * n)))
    t = np.arange(n) / rate_hz
    tc = t - t.mean()
    slope = float(np.dot(tc, x - x.mean()) / np.dot(tc, tc)) if n > 1 else math.nan
    return {'first': float(np.mean(x[:k])), 'last': float(np.mean(x[-k:]))}, slope


def _mean_noise(terms, rate_hz, duration_s):
    """
    Variance of the first tenth's mean from the noise within the run.

    The Allan variance at averaging time T is the variance of the mean over T for white noise
    and, for a walk started at zero, K^2 T / 3, the variance of its mean: it stands for both.
    """
    from ..terms import model_avar
    avar = model_avar(terms, np.array([duration_s * SEGMENT]), rate_hz)
    return {'first': float(avar[0])}


def measure_recording(recording, model, z_crit=3.0, alpha=ALPHA, points_per_decade=10,
                      min_clusters=10):
    """
    Evidence of one :class:`Recording` against ``model`` (a NoiseModel, SI, continuous time).

    Returns ``{axis: AxisEvidence}`` for the axes both have (the model's terms on that axis;
    an axis with a turn-on bias but no terms gets the raw statistics only).  ``z_crit`` is the
    decision level (sigmas) of the absent-term upper limit.
    """
    data = np.asarray(recording.data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    rate = float(recording.rate_hz)
    measured = recording.measured
    if measured is None:
        measured = allan_deviation(data, rate, points_per_decade=points_per_decade,
                                   min_clusters=min_clusters, axes=tuple(recording.axes))
    if measured.tau.size < 6:
        raise ValueError(f'only {measured.tau.size} averaging times: the record is too short '
                         'for a discrepancy analysis')
    out = {}
    for j, axis in enumerate(recording.axes):
        stated, zeroed = split_zeroed(model.terms.get(axis, {}))
        if not (stated or zeroed) and axis not in model.turn_on_bias:
            continue
        x = data[:, j]
        ev = AxisEvidence(axis, rate, recording.duration_s, stated, {}, zeroed=zeroed)
        ev.means, ev.slope_per_s = _raw_statistics(x, rate)
        ev.rms = float(np.std(x))
        ev.tau_range = (float(measured.tau[0]), float(measured.tau[-1]))
        if recording.stated_variance and axis in recording.stated_variance:
            ev.stated_variance = recording.stated_variance[axis]
        ev.white_variance = (float(measured.avar[0, j]), float(measured.edf[0, j]))
        adev = measured.adev[:, j]
        if stated and np.all(np.isfinite(adev) & (adev > 0)):
            _fit_axis(ev, _Axis(np.log(adev), measured, j, rate), z_crit, alpha)
        out[axis] = ev
    return out


def _free_gauss_markov(ax, names, fit, fixed):
    """
    Free a stated Gauss-Markov's tau_c and keep it when that fits significantly better.

    Returns ``(positions to hold, fit, (free fit, p-value) or None)``: the freed tau_c when its
    improvement has p below :data:`ADOPT_P`, else the ones given.  A wrong correlation time is
    then not taken for a missing effect (a ramp standing in for a hump that keeps rising).
    """
    if 'gauss_markov' not in fixed:
        return fixed, fit, None
    free, p = _free_position(ax, names, fit, fixed)
    if p >= ADOPT_P:
        return fixed, fit, (free, p)
    adopted = dict(fixed, gauss_markov=free.terms['gauss_markov']['tau_c'])
    return adopted, ax.fit(names, free.terms, adopted)[1], (free, p)


def _fit_axis(ev, ax, z_crit, alpha):
    """Fill the Allan-variance evidence of one axis (see the module docstring)."""
    measured, y, rate, stated = ax.measured, ax.y, ax.rate, ev.stated
    tau = measured.tau
    names = list(stated)
    fixed = _positions(stated)
    ev.gap_stated = measure_gap(y, model_band(stated, tau, measured.m, measured.n_samples,
                                              rate), alpha).value
    first = ax.fit(names, stated, fixed)
    held, fit, freed = _free_gauss_markov(ax, names, first[1], fixed)
    replaced = None
    if 'rate_random_walk' in stated and 'gauss_markov' not in stated:
        ev.process, bounded = _bounded_walk(ax, names, fit, fixed)
        if ev.process is not None:
            # the stated walk stands in for the data's bounded bias; the process is kept in
            # the walk's place (with its fitted tau_c) for what follows, so that a missing
            # effect is not invented to bend the walk, and its stated K is not scaled
            ev.process['estimate'].log -= math.log(stated['rate_random_walk']['value'])
            if ev.process['p_value'] < ADOPT_P:
                replaced = 'rate_random_walk'
                names = [t for t in names if t != replaced] + ['gauss_markov']
                fixed = dict(fixed, gauss_markov=bounded.terms['gauss_markov']['tau_c'])
                held = dict(fixed)
                fit = bounded
                first = ax.fit(names, bounded.terms, fixed)
    # effects the stated terms lack: only when the refitted stated terms leave the band
    for _ in range(MAX_MISSING):
        band = model_band(fit.terms, tau, measured.m, measured.n_samples, rate)
        gap = measure_gap(y, band, alpha)
        if gap.consistent:
            break
        cands = evaluate_candidates(y, band, gap, rate, fit.terms, alpha)
        winner = next((c for c in cands if c.significant and c.effect in c.fit.terms), None)
        if winner is None:
            break
        added = winner.effect
        ev.missing.append({'term': added, 'params': dict(winner.fit.terms[added]),
                           'p_value': winner.p_value,
                           'ci': {k: list(v) for k, v in winner.fit.intervals[added].items()}})
        names.append(added)
        if TERMS[added].position:
            position = TERMS[added].unpack(winner.fit.terms[added])[1]
            fixed[added] = held[added] = position
        init = dict(fit.terms)
        init[added] = winner.fit.terms[added]
        fit = ax.fit(names, init, held)[1]
    band = model_band(fit.terms, tau, measured.m, measured.n_samples, rate)
    gap = measure_gap(y, band, alpha)
    ev.gap_fitted, ev.consistent_fitted = gap.value, gap.consistent
    ev.fitted = fit.terms
    ev.mean_noise_var = _mean_noise(fit.terms, rate, ev.duration_s)
    # the factors: amplitudes with the stated positions (and any added effect's)
    if ev.missing:
        prob, fit = ax.fit(names, fit.terms, fixed)
        freed = None  # the freed tau_c is tried again beside the added effects
    else:
        prob, fit = first
    needed = set()
    for term, params in stated.items():
        if term == replaced:
            continue
        a0 = amplitude(params, term)
        p_drop = _drop_test(prob, fit, names, term, fixed)
        if p_drop > NOT_NEEDED_P:
            # the data do not need the term: its fitted size is no measurement
            ev.absent[term] = _absent(prob, fit, names, term, fixed, a0, z_crit)
            continue
        if p_drop > NEEDED_P:
            continue  # seen, but not clearly enough to be measured
        needed.add(term)
        ev.scales[term] = LogEstimate(math.log(amplitude(fit.terms[term], term) / a0),
                                      _log_sd(fit, term, 'amp') * AMPLITUDE_SE_INFLATION,
                                      rate)
    if 'gauss_markov' in needed:
        _gauss_markov_tests(ev, ax, names, fit, fixed, freed)
