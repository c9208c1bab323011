"""The discrepancy workflow: where do a noise model and measured data disagree, and why.

Given measured IMU samples and a starting noise model (a model file, or a few named terms fitted
to the data), the workflow

1. computes the measured overlapping Allan deviation (:func:`~imu_allan.core.allan.
   allan_deviation`);
2. builds, for every averaging time, where the measured log-deviation should lie if the model
   were complete: the analytic curve of the model (:mod:`imu_allan.core.terms`) corrected for the
   bias of the log of a chi-square estimate, with a spread from the model's equivalent degrees of
   freedom (Greenhall EDF of each term, :mod:`imu_allan.core.edf`), pooled with ``n_sims``
   independent simulations of the model at the measured rate and length through the same
   estimator;
3. measures the gap per averaging time, z_i = (ln adev_meas - centre_i) / spread_i, and one
   number per axis, G = sqrt(mean_i z_i^2), which is about 1 when the model is complete; its
   significance uses the effective number of independent averaging times
   T_eff = T^2 / sum_ij rho_ij^2 (rho: the measured correlation of estimates between averaging
   times, :func:`~imu_allan.core.fit.correlation_matrix`), G^2 T_eff ~ chi-square(T_eff);
4. locates the band of averaging times where the data leave the model's band (smoothed |z| > 2
   around the largest excursion);
5. lets every effect the model lacks compete: each is added and all terms are refitted (a
   weighted least-squares fit in log-deviation, the same metric as the gap); with the effective
   Akaike criterion AIC = (T_eff / T) Q + 2 k (Q = sum z^2 after the fit, k parameters), the
   winner is the candidate whose AIC drop per added parameter is largest, and it is only
   accepted if its improvement is significant (a Satterthwaite chi-square test of Delta Q under
   the correlated null, Bonferroni over the candidates, and for Gauss-Markov / sinusoid also
   over the T_eff positions their hump could take);
6. adds it, refits, re-simulates, re-measures, and repeats until nothing significant is left.

Everything is SI (rad/s, m/s^2, s, Hz) and ROS-free.  ``docs/discrepancy.md`` explains the method
and the validation results.
"""

from dataclasses import dataclass, field
import functools
import math

import numpy as np
from scipy.optimize import least_squares, nnls
from scipy.special import digamma, polygamma
from scipy.stats import chi2

from . import terms as _terms
from .allan import allan_deviation, avar_fast
from .edf import edf_oadev
from .fit import correlation_matrix
from .model import ModelError, NoiseModel
from .simulate import simulate
from .units import ALL_TERMS, AXES, si_unit, TERM_PARAMETERS

#: Default starting terms: the thesis's own model (white noise + bias instability).
DEFAULT_START = ('white_noise', 'bias_instability')
#: Power-law exponent (frequency PSD) of each random term, for the EDF and the correlation.
TERM_ALPHA = {'quantization': 2, 'white_noise': 0, 'bias_instability': -1, 'rate_random_walk': -2}
#: Terms whose Allan variance estimate carries no randomness of its own.
DETERMINISTIC = ('rate_ramp', 'sinusoid')
#: Terms with a position parameter (their hump can sit anywhere in the measured span).
NONLINEAR = {'gauss_markov': 'tau_c', 'sinusoid': 'frequency_hz'}
#: Weight (pseudo-observations) of the analytic EDF spread when pooled with simulations.
PRIOR_WEIGHT = 16.0
#: Default significance level: for calling a model inconsistent and for adding an effect.
ALPHA = 0.01
#: Ratio of the ADEV peak time to tau_c (Gauss-Markov) and to 1/f0 (sinusoid).
GM_PEAK = 1.8926
SINE_PEAK = 0.37101
_Z68 = 1.0
_Z95 = 1.959964


# ---------------------------------------------------------------------------------------------
# The band: where the measured log-deviation should lie if the model were complete


@functools.lru_cache(maxsize=4096)
def _edf(alpha, m, n_phase):
    return edf_oadev(alpha, int(m), int(n_phase))


def _term_edf(term, params, tau, ms, n_samples):
    """EDF of the AVAR estimate if ``term`` alone were present; inf for deterministic terms."""
    if term in DETERMINISTIC:
        return np.full(tau.shape, np.inf)
    if term == 'gauss_markov':  # random-walk-like below its correlation time, white above
        alphas = np.where(tau >= params['tau_c'], 0, -2)
    else:
        alphas = np.full(tau.shape, TERM_ALPHA[term])
    return np.array([_edf(int(a), int(m), n_samples + 1) for a, m in zip(alphas, ms)])


def _term_alpha(term, params, tau):
    if term == 'gauss_markov':
        return np.where(tau >= params['tau_c'], 0, -2)
    return np.full(tau.shape, TERM_ALPHA.get(term, 0))


@dataclass
class Band:
    """Expected measured log-deviation of one axis under a model.

    Attributes
    ----------
    tau : numpy.ndarray
        Averaging times, s.
    avar : numpy.ndarray
        Analytic model AVAR (unit^2).
    edf : numpy.ndarray
        Model EDF of each AVAR estimate (harmonic mix of the terms' EDFs weighted by their AVAR
        share).
    alpha : numpy.ndarray
        Exponent of the dominant random term (drives the correlation between averaging times).
    center : numpy.ndarray
        Expected ln(adev) of the estimator: 0.5 ln AVAR + 0.5 (psi(nu/2) - ln(nu/2)).
    sd : numpy.ndarray
        Standard deviation of ln(adev) (analytic 0.5 sqrt(psi'(nu/2)), pooled with simulations).
    sims : numpy.ndarray or None
        (K, T) ln(adev) of the simulated runs.

    """

    tau: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    center: np.ndarray
    sd: np.ndarray
    sims: np.ndarray = None

    @property
    def corr(self):
        """Correlation of the estimates between averaging times."""
        return correlation_matrix(self.tau, self.alpha)

    def effective_count(self):
        """T_eff = T^2 / sum rho_ij^2: independent averaging times equivalent to the curve."""
        r = self.corr
        return self.tau.size ** 2 / float(np.sum(r * r))

    def adev_band(self, z=_Z95):
        """(low, centre, high) of the deviation at +-z spreads (unit of the samples)."""
        return (np.exp(self.center - z * self.sd), np.exp(self.center),
                np.exp(self.center + z * self.sd))


def model_band(axis_terms, tau, ms, n_samples, rate_hz):
    """Analytic :class:`Band` of one axis (``axis_terms``: ``{term: params}``, SI)."""
    tau = np.asarray(tau, dtype=float)
    contrib = {t: np.maximum(_terms.term_avar(t, p, tau, rate_hz), 0.0)
               for t, p in axis_terms.items()}
    total = np.zeros(tau.shape)
    for value in contrib.values():
        total = total + value
    total = np.maximum(total, 1e-300)
    inv_nu = np.zeros(tau.shape)
    best = np.zeros(tau.shape)
    alpha = np.zeros(tau.shape, dtype=int)
    for term, value in contrib.items():
        nu = _term_edf(term, axis_terms[term], tau, ms, n_samples)
        with np.errstate(invalid='ignore', divide='ignore'):
            inv_nu += np.where(np.isfinite(nu), (value / total) / nu, 0.0)
        if term not in DETERMINISTIC:
            dom = value > best
            alpha = np.where(dom, _term_alpha(term, axis_terms[term], tau), alpha)
            best = np.maximum(best, value)
    # a purely deterministic curve still has rounding-level scatter: cap the EDF
    nu = 1.0 / np.maximum(inv_nu, 1e-9)
    half = nu / 2.0
    center = 0.5 * np.log(total) + 0.5 * (digamma(half) - np.log(half))
    sd = 0.5 * np.sqrt(polygamma(1, half))
    return Band(tau, total, nu, alpha, center, sd)


def pool_simulations(band, sims):
    """Pool the analytic spread with simulated ln(adev) runs (K, T) about the analytic centre."""
    sims = np.atleast_2d(sims)
    k = sims.shape[0]
    dev2 = np.sum((sims - band.center) ** 2, axis=0)
    sd = np.sqrt((PRIOR_WEIGHT * band.sd ** 2 + dev2) / (PRIOR_WEIGHT + k))
    return Band(band.tau, band.avar, band.edf, band.alpha, band.center, sd, sims)


@dataclass
class Gap:
    """Model-vs-data gap of one axis.

    ``z`` per averaging time (units of the spread), ``value`` = sqrt(mean z^2) (about 1 when
    consistent), ``t_eff`` effective independent averaging times, ``p_value`` of
    ``value^2 t_eff`` under chi-square(t_eff), ``threshold`` the largest ``value`` still called
    consistent at the 1 - ``ALPHA`` level, ``tau_range`` the band where the data leave the model
    (s, or None).
    """

    z: np.ndarray
    value: float
    t_eff: float
    p_value: float
    threshold: float
    consistent: bool
    tau_range: tuple = None
    peak_tau: float = math.nan


def _smooth(z):
    if z.size < 3:
        return z.copy()
    padded = np.concatenate([[z[0]], z, [z[-1]]])
    return 0.25 * padded[:-2] + 0.5 * padded[1:-1] + 0.25 * padded[2:]


def excursion_band(tau, z, level=2.0):
    """Contiguous band of averaging times around the largest smoothed excursion |z| > level.

    Returns ``((tau_lo, tau_hi), tau_peak)``; the band is None when nothing exceeds ``level``.
    """
    zs = np.abs(_smooth(z))
    k = int(np.argmax(zs))
    if zs[k] <= level:
        return None, float(tau[k])
    lo = k
    while lo > 0 and zs[lo - 1] > level:
        lo -= 1
    hi = k
    while hi < zs.size - 1 and zs[hi + 1] > level:
        hi += 1
    return (float(tau[lo]), float(tau[hi])), float(tau[k])


def measure_gap(y, band, alpha=ALPHA):
    """Gap of measured ln(adev) ``y`` against a :class:`Band`."""
    z = (y - band.center) / band.sd
    value = float(np.sqrt(np.mean(z * z)))
    t_eff = band.effective_count()
    p = float(chi2.sf(value * value * t_eff, t_eff))
    threshold = float(math.sqrt(chi2.ppf(1.0 - alpha, t_eff) / t_eff))
    tau_range, peak = excursion_band(band.tau, z)
    return Gap(z, value, t_eff, p, threshold, p >= alpha, tau_range, peak)


# ---------------------------------------------------------------------------------------------
# Fitting in log-deviation with the gap's own metric


def _shape(term, tau, rate_hz, position=None):
    """AVAR per unit squared amplitude of a term (position: tau_c or f0 for nonlinear terms)."""
    if term == 'gauss_markov':
        return _terms.gauss_markov_shape(tau, position)
    if term == 'sinusoid':
        return _terms.sinusoid_shape(tau, position)
    return _terms.linear_shape(term, tau, rate_hz)


def _pack(term, amplitude, position=None):
    if term == 'gauss_markov':
        return {'sigma': amplitude, 'tau_c': position}
    if term == 'sinusoid':
        return {'amplitude': amplitude, 'frequency_hz': position}
    return {'value': amplitude}


def _unpack(term, params):
    if term == 'gauss_markov':
        return params['sigma'], params['tau_c']
    if term == 'sinusoid':
        return params['amplitude'], params['frequency_hz']
    return params['value'], None


def position_range(term, tau):
    """Allowed position of a hump term: its ADEV peak must lie inside the measured span."""
    t0, t1 = float(tau[0]), float(tau[-1])
    if term == 'gauss_markov':
        return t0 / GM_PEAK, t1 / GM_PEAK
    return SINE_PEAK / t1, SINE_PEAK / t0


@dataclass
class AxisFit:
    """Result of fitting a list of terms to one axis in log-deviation."""

    terms: dict
    q: float
    z: np.ndarray
    jac: np.ndarray
    names: list
    cov: np.ndarray
    intervals68: dict = field(default_factory=dict)
    intervals95: dict = field(default_factory=dict)
    at_bound: dict = field(default_factory=dict)


class FitProblem:
    """Measured ln(adev) of one axis with a fixed reference spread (from the current model)."""

    def __init__(self, y, tau, rate_hz, band):
        self.y = y
        self.tau = tau
        self.rate_hz = rate_hz
        self.bias = band.center - 0.5 * np.log(band.avar)
        self.sd = band.sd
        self.corr = band.corr
        self.t_eff = band.effective_count()
        # the AVAR level each point asks for, used to scale amplitudes and start the fit
        self.target = np.exp(2.0 * (y - self.bias))
        self._shapes = {}

    def shape(self, term, position=None):
        """AVAR per unit squared amplitude at this problem's tau (cached for fixed shapes)."""
        if term in NONLINEAR:
            return _shape(term, self.tau, self.rate_hz, position)
        if term not in self._shapes:
            self._shapes[term] = _shape(term, self.tau, self.rate_hz)
        return self._shapes[term]

    def residual(self, avar):
        return (self.y - 0.5 * np.log(np.maximum(avar, 1e-300)) - self.bias) / self.sd

    def amplitude_bounds(self, shape):
        ok = shape > 0
        top = math.sqrt(float(np.min(self.target[ok] / shape[ok]))) if ok.any() else 1.0
        return top * 1e-4, top * 30.0


def _nnls_start(prob, names, positions):
    """Relative-error NNLS of squared amplitudes for fixed positions; returns (amps, Q)."""
    shapes = np.column_stack([prob.shape(t, positions.get(t)) for t in names])
    w = 1.0 / (2.0 * prob.target * prob.sd)
    a = shapes * w[:, None]
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef = nnls(a / scale, prob.target * w, maxiter=50 * len(names))[0] / scale
    avar = shapes @ coef
    if not np.all(avar > 0):
        return np.sqrt(coef), math.inf
    z = prob.residual(avar)
    return np.sqrt(coef), float(z @ z)


def fit_terms(prob, names, init=None, hints=None):
    """Fit ``names`` (all amplitudes and positions free) to a :class:`FitProblem`.

    ``init`` ({term: params}) and ``hints`` ({term: position}) seed the search; hump terms are
    started from a grid of positions over the measured span plus the hints.
    """
    names = [t for t in ALL_TERMS if t in names]
    init = init or {}
    hints = hints or {}
    nl = [t for t in names if t in NONLINEAR]
    grids = []
    for t in nl:
        lo, hi = position_range(t, prob.tau)
        grid = list(np.geomspace(lo, hi, 14))
        for extra in (hints.get(t), _unpack(t, init[t])[1] if t in init else None):
            if extra is not None and lo <= extra <= hi:
                grid.append(extra)
        grids.append(grid)
    starts = []
    for combo in (np.array(np.meshgrid(*grids)).reshape(len(nl), -1).T if nl else [()]):
        positions = dict(zip(nl, combo))
        amps, q = _nnls_start(prob, names, positions)
        starts.append((q, positions, amps))
    starts.sort(key=lambda s: s[0])
    starts = starts[:2]
    if init and all(t in init for t in names):
        positions = {t: _unpack(t, init[t])[1] for t in nl}
        amps = np.array([_unpack(t, init[t])[0] for t in names])
        starts.append((math.inf, positions, amps))

    # parameter vector: ln amplitude per term, then ln position per hump term
    bounds_lo, bounds_hi = [], []
    for t in names:
        shape = prob.shape(t, math.sqrt(np.prod(position_range(t, prob.tau)))
                           if t in nl else None)
        if t in nl:  # amplitude bound from the hump's peak level, position-independent
            peak = float(np.max(shape))
            top = math.sqrt(float(np.max(prob.target)) / peak)
            lo, hi = top * 1e-5, top * 30.0
        else:
            lo, hi = prob.amplitude_bounds(shape)
        bounds_lo.append(math.log(lo))
        bounds_hi.append(math.log(hi))
    for t in nl:
        lo, hi = position_range(t, prob.tau)
        bounds_lo.append(math.log(lo))
        bounds_hi.append(math.log(hi))
    bounds_lo, bounds_hi = np.array(bounds_lo), np.array(bounds_hi)

    def model(theta):
        amps = np.exp(theta[:len(names)])
        pos = dict(zip(nl, np.exp(theta[len(names):])))
        avar = np.zeros(prob.tau.shape)
        for t, a in zip(names, amps):
            avar = avar + a * a * prob.shape(t, pos.get(t))
        return avar

    def fun(theta):
        return prob.residual(model(theta))

    best = None
    for _, positions, amps in starts:
        x0 = np.concatenate([np.log(np.maximum(amps, 1e-300)),
                             np.log([positions[t] for t in nl])]) if nl else \
            np.log(np.maximum(amps, 1e-300))
        span = bounds_hi - bounds_lo
        x0 = np.clip(x0, bounds_lo + 1e-3 * span, bounds_hi - 1e-3 * span)
        sol = least_squares(fun, x0, bounds=(bounds_lo, bounds_hi), method='trf',
                            x_scale=1.0, max_nfev=300)
        q = float(sol.fun @ sol.fun)
        if best is None or q < best[0]:
            best = (q, sol)
    q, sol = best
    theta = sol.x
    jac = sol.jac
    params = {}
    amps = np.exp(theta[:len(names)])
    pos = dict(zip(nl, np.exp(theta[len(names):])))
    for t, a in zip(names, amps):
        params[t] = _pack(t, float(a), float(pos[t]) if t in pos else None)
    cov = _sandwich(jac, prob.corr)
    labels = [(t, 'amp') for t in names] + [(t, 'pos') for t in nl]
    fit = AxisFit(params, q, sol.fun, jac, labels, cov)
    span = bounds_hi - bounds_lo
    for i, (t, kind) in enumerate(labels):
        pname = TERM_PARAMETERS[t][0 if kind == 'amp' else 1]
        sd = math.sqrt(max(cov[i, i], 0.0)) if np.isfinite(cov[i, i]) else math.inf
        fit.intervals68.setdefault(t, {})[pname] = _log_interval(theta[i], _Z68 * sd)
        fit.intervals95.setdefault(t, {})[pname] = _log_interval(theta[i], _Z95 * sd)
        fit.at_bound.setdefault(t, {})[pname] = bool(
            theta[i] - bounds_lo[i] < 1e-2 * span[i] or bounds_hi[i] - theta[i] < 1e-2 * span[i])
    return fit


def _log_interval(log_value, half_width):
    """Interval exp(log_value -+ half_width), clipped to the float range (0 .. 1e300)."""
    if not math.isfinite(half_width):
        return 0.0, math.inf
    lo = math.exp(max(log_value - half_width, -700.0))
    hi = math.exp(min(log_value + half_width, 690.0))
    return float(lo), float(hi)


def _sandwich(jac, corr):
    """Covariance of the working-independence least-squares estimate under correlation."""
    a = jac.T @ jac
    inv = np.linalg.pinv(a)
    with np.errstate(over='ignore', invalid='ignore'):
        return inv @ (jac.T @ corr @ jac) @ inv


def improvement_test(delta_q, jac_nuisance, jac_added, corr):
    """p-value of a drop ``delta_q`` in sum z^2 when columns ``jac_added`` are added.

    Under the null (the smaller model is complete) z ~ N(0, R) and the drop is the quadratic
    form z' P z with P the projection on the added directions orthogonal to the nuisance ones;
    its distribution is matched by c chi-square(h) (Satterthwaite) with c = tr(PRPR)/tr(PR),
    h = tr(PR)^2 / tr(PRPR).  Returns ``(p, h)``.
    """
    if delta_q <= 0:
        return 1.0, 0.0
    x = jac_added
    if jac_nuisance is not None and jac_nuisance.size:
        x = x - jac_nuisance @ (np.linalg.pinv(jac_nuisance) @ x)
    if not np.any(np.abs(x) > 0):
        return 1.0, 0.0
    proj = x @ np.linalg.pinv(x)
    pr = proj @ corr
    e = float(np.trace(pr))
    v = float(np.sum(pr * pr.T))
    if e <= 0 or v <= 0:
        return 1.0, 0.0
    c, h = v / e, e * e / v
    return float(chi2.sf(delta_q / c, h)), h


# ---------------------------------------------------------------------------------------------
# One step: let the candidates compete


@dataclass
class Candidate:
    """A candidate effect fitted together with the current terms."""

    effect: str
    fit: AxisFit
    delta_q: float
    k: int
    ic: float
    p_value: float
    significant: bool
    gain: float = 0.0  # (AIC of the current terms - AIC with the candidate) / k


@dataclass
class Step:
    """One accepted addition to an axis's model (JSON-ready through :meth:`to_dict`)."""

    axis: str
    effect: str
    tau_range: tuple
    gap_before: float
    gap_after: float
    parameters: dict
    terms_after: dict
    p_value: float
    excess_slope: float
    candidates: list
    index: int = 0
    excursion: tuple = None
    snapshot: int = 0  # index of the snapshot before the step (the one after is snapshot + 1)

    def to_dict(self):
        """Contract fields plus the evidence behind the choice."""
        return {'axis': self.axis, 'effect': self.effect,
                'tau_range_s': list(self.tau_range) if self.tau_range else None,
                'gap_before': self.gap_before, 'gap_after': self.gap_after,
                'parameters': self.parameters, 'p_value': self.p_value,
                'excursion_tau_range_s': (list(self.excursion) if self.excursion else None),
                'excess_adev_slope': (None if not math.isfinite(self.excess_slope)
                                      else self.excess_slope),
                'terms_after': {t: dict(p) for t, p in self.terms_after.items()},
                'candidates': self.candidates}


def _excess_slope(tau, y, band, tau_range):
    """Log-log slope of the measured ADEV excess over the model inside the band (NaN if none)."""
    if not tau_range:
        return math.nan
    sel = (tau >= tau_range[0]) & (tau <= tau_range[1])
    excess = np.exp(2.0 * (y - band.center + 0.5 * np.log(band.avar))) - band.avar
    sel &= excess > 0
    if sel.sum() < 3:
        return math.nan
    slope = np.polyfit(np.log(tau[sel]), np.log(excess[sel]), 1)[0]
    return float(slope / 2.0)


def _effect_band(tau, band, axis_terms, effect, rate_hz):
    """Averaging times where ``effect`` moves the model's ln(adev) by more than one spread."""
    if effect not in axis_terms:
        return None
    total = _terms.model_avar(axis_terms, tau, rate_hz)
    without = _terms.model_avar({t: p for t, p in axis_terms.items() if t != effect}, tau,
                                rate_hz)
    shift = 0.5 * np.log(np.maximum(total, 1e-300) / np.maximum(without, 1e-300))
    sel = np.nonzero(shift > band.sd)[0]
    if sel.size == 0:
        return None
    return float(tau[sel[0]]), float(tau[sel[-1]])


def _param_report(axis, term, fit):
    out = {}
    for pname, value in fit.terms[term].items():
        unit = 's' if pname == 'tau_c' else 'Hz' if pname == 'frequency_hz' else \
            si_unit(axis, term)
        out[pname] = {'value': value, 'unit': unit,
                      'ci': list(fit.intervals68[term][pname]),
                      'ci95': list(fit.intervals95[term][pname]),
                      'at_bound': fit.at_bound[term][pname]}
    return out


def _n_params(term):
    return len(TERM_PARAMETERS[term])


def evaluate_candidates(y, tau, rate_hz, band, current, alpha=ALPHA, fixed=False,
                        gap=None):
    """Fit every effect the axis lacks; return (candidates, best first; baseline fit).

    ``current`` is the axis's ``{term: params}``; with ``fixed`` the current parameters came
    from a model file and a pure refit ('recalibration') competes as well.
    """
    prob = FitProblem(y, tau, rate_hz, band)
    gap = gap or measure_gap(y, band, alpha)
    hints = {'gauss_markov': gap.peak_tau / GM_PEAK, 'sinusoid': SINE_PEAK / gap.peak_tau}
    base_names = list(current)
    scale = prob.t_eff / tau.size
    results = []
    if base_names:
        base = fit_terms(prob, base_names, init=current)
    else:
        base = None
    q0 = base.q if base else float(np.sum(prob.residual(np.full(tau.shape, 1e-300)) ** 2))
    others = [t for t in ALL_TERMS if t not in current]
    n_tests = len(others) + (1 if fixed and base_names else 0)
    for term in others:
        fit = fit_terms(prob, base_names + [term], init=current, hints=hints)
        delta = q0 - fit.q
        k = _n_params(term)
        cols = [i for i, (t, _) in enumerate(fit.names) if t == term]
        ncols = [i for i, (t, _) in enumerate(fit.names) if t != term]
        p, _ = improvement_test(delta, fit.jac[:, ncols] if ncols else None,
                                fit.jac[:, cols], prob.corr)
        if term in NONLINEAR:  # the hump's position was searched over the whole span
            p = min(1.0, p * max(prob.t_eff, 1.0))
        p_adj = min(1.0, p * n_tests)
        results.append(Candidate(term, fit, delta, k, scale * fit.q + 2.0 * k, p_adj,
                                 p_adj < alpha, (scale * delta - 2.0 * k) / k))
    if fixed and base is not None:
        q_fixed = float(np.sum(prob.residual(band.avar) ** 2))
        delta = q_fixed - base.q
        p, _ = improvement_test(delta, None, base.jac, prob.corr)
        p_adj = min(1.0, p * n_tests)
        k = sum(_n_params(t) for t in base_names)
        results.append(Candidate('recalibration', base, delta, k, scale * base.q + 2.0 * k,
                                 p_adj, p_adj < alpha, (scale * delta - 2.0 * k) / k))
    # the effect that lowers the (effective) AIC most per added parameter ranks first
    results.sort(key=lambda c: -c.gain)
    return results, base


# ---------------------------------------------------------------------------------------------
# The workflow


@dataclass
class Snapshot:
    """State of every axis in one round (for plots): model terms, band and gap."""

    terms: dict
    bands: dict
    gaps: dict


@dataclass
class DiscrepancyResult:
    """Everything the workflow found; :meth:`to_dict` gives the contract JSON."""

    measured: object
    axes: list
    initial_model: NoiseModel
    final_model: NoiseModel
    steps: list
    initial_gaps: dict
    final_gaps: dict
    snapshots: list
    n_sims: int
    start: str
    notes: list = field(default_factory=list)

    @property
    def y(self):
        """Measured ln(adev) (T, A)."""
        return np.log(self.measured.adev)

    def effects(self, axis):
        """Names of the effects added to one axis, in order."""
        return [s.effect for s in self.steps if s.axis == axis]

    def to_dict(self):
        """Report dictionary (``discrepancy --json``)."""
        def union(model):
            present = {t for a in self.axes for t in model.terms.get(a, {})}
            return [t for t in ALL_TERMS if t in present]
        m = self.measured
        gaps = {}
        for a in self.axes:
            g0, g1 = self.initial_gaps[a], self.final_gaps[a]
            gaps[a] = {'initial': g0.value, 'final': g1.value,
                       'consistent': g1.consistent, 'p_value': g1.p_value,
                       'threshold': g1.threshold, 'effective_taus': g1.t_eff,
                       'initial_tau_range_s': list(g0.tau_range) if g0.tau_range else None,
                       'final_tau_range_s': list(g1.tau_range) if g1.tau_range else None}
        return {
            'n_samples': int(m.n_samples), 'sample_rate_hz': float(m.rate_hz),
            'duration_s': float(m.n_samples / m.rate_hz), 'start': self.start,
            'initial_terms': union(self.initial_model), 'final_terms': union(self.final_model),
            'initial_model': self.initial_model.to_dict()['axes'],
            'final_model': self.final_model.to_dict()['axes'],
            'steps': [s.to_dict() for s in self.steps],
            'gap': gaps,
            'method': {'gap': 'sqrt(mean_i z_i^2), z_i = (ln adev_meas - E ln adev_model) / '
                              'sd(ln adev_model)',
                       'consistent_if': f'chi2.sf(gap^2 T_eff, T_eff) >= {ALPHA}',
                       'n_sims': self.n_sims, 'alpha': ALPHA},
            'notes': list(self.notes),
        }


def _measured_band(measured, j):
    """Band from the measured curve itself (used only to start a --terms fit)."""
    nu = np.maximum(measured.edf[:, j], 1.0)
    half = nu / 2.0
    center = np.log(measured.adev[:, j]) + 0.5 * (digamma(half) - np.log(half))
    return Band(measured.tau, measured.avar[:, j], nu, measured.alpha[:, j], center,
                0.5 * np.sqrt(polygamma(1, half)))


def _simulate_axis(axis_terms, axis, measured, n_sims, rng):
    """ln(adev) of ``n_sims`` simulated runs of one axis through the same estimator (K, T)."""
    model = NoiseModel({axis: axis_terms}, measured.rate_hz)
    runs = np.empty((n_sims, measured.tau.size))
    for k in range(n_sims):
        x = simulate(model, measured.n_samples, measured.rate_hz, seed=rng, axes=[axis])
        # the AVAR kernel of allan_deviation itself, on the measured averaging factors
        runs[k] = 0.5 * np.log(np.maximum(avar_fast(x, measured.m)[:, 0], 1e-300))
    return runs


def _bands(current, axes, measured, n_sims, rng, previous=None):
    """Analytic bands of every axis pooled with ``n_sims`` simulated runs.

    Axes whose terms did not change since ``previous`` (a dict of bands) keep their bands:
    re-simulating an unchanged model would only add noise and time.
    """
    bands = {}
    for axis in axes:
        old = (previous or {}).get(axis)
        if old is not None and old[0] == current[axis]:
            bands[axis] = old[1]
            continue
        band = model_band(current[axis], measured.tau, measured.m, measured.n_samples,
                          measured.rate_hz)
        if n_sims > 0:
            band = pool_simulations(band, _simulate_axis(current[axis], axis, measured,
                                                         n_sims, rng))
        bands[axis] = band
    return bands


def start_model(measured, axes, terms, alpha=ALPHA):
    """Fit only ``terms`` to every axis (the ``--terms`` start), in the gap's own metric."""
    out = {}
    for axis in axes:
        j = list(measured.axes).index(axis)
        y = np.log(measured.adev[:, j])
        band = _measured_band(measured, j)
        fit = fit_terms(FitProblem(y, measured.tau, measured.rate_hz, band), list(terms))
        # second pass with the spread the fitted model itself implies
        band = model_band(fit.terms, measured.tau, measured.m, measured.n_samples,
                          measured.rate_hz)
        fit = fit_terms(FitProblem(y, measured.tau, measured.rate_hz, band), list(terms),
                        init=fit.terms)
        out[axis] = fit.terms
    return NoiseModel(out, measured.rate_hz)


def run_discrepancy(data, rate_hz, axes=None, model=None, terms=None, n_sims=4, seed=0,
                    max_steps=4, alpha=ALPHA, points_per_decade=10, min_clusters=10,
                    measured=None):
    """Run the discrepancy workflow on rate samples.

    Parameters
    ----------
    data : array_like
        (n_samples, n_axes) rate samples, SI (rad/s, m/s^2).
    rate_hz : float
        Sample rate, Hz.
    axes : sequence of str, optional
        Column names (default: the first n_axes of the package axis order).
    model : NoiseModel, optional
        Starting model (parameters as given, e.g. a datasheet budget).
    terms : sequence of str, optional
        Starting terms fitted to the data (default: white noise + bias instability when no
        model is given).
    n_sims : int
        Simulated runs per round pooled into the spread (0: analytic spread only).
    seed : int
        Seed of the simulations.
    max_steps : int
        Most effects added per axis.
    alpha : float
        Significance level for "inconsistent" and for adding an effect.
    points_per_decade, min_clusters : int
        Averaging-time grid of the estimator.
    measured : AllanResult, optional
        Precomputed measured curve (skips the estimator).

    Returns
    -------
    DiscrepancyResult

    """
    data = None if data is None else np.asarray(data, dtype=float)
    if measured is None:
        if data.ndim == 1:
            data = data[:, None]
        axes = tuple(axes) if axes is not None else AXES[:data.shape[1]]
        measured = allan_deviation(data, rate_hz, points_per_decade=points_per_decade,
                                   min_clusters=min_clusters, axes=axes)
    axes_all = list(measured.axes)
    if measured.tau.size < 6:
        raise ValueError(f'only {measured.tau.size} averaging times: the record is too short '
                         'for a discrepancy analysis')
    notes = []
    dead = [a for j, a in enumerate(axes_all)
            if not np.all(np.isfinite(measured.adev[:, j]) & (measured.adev[:, j] > 0))]
    if dead:  # a constant (stuck or absent) channel has no noise to compare
        notes.append(f'{", ".join(dead)}: Allan deviation is zero (constant signal): skipped')
        axes_all = [a for a in axes_all if a not in dead]
        if not axes_all:
            raise ValueError('every axis is constant: no noise to analyse')
    if model is not None:
        if isinstance(model, dict):
            model = NoiseModel.from_dict(model)
        work_axes = [a for a in axes_all if model.terms.get(a)]
        skipped = [a for a in axes_all if a not in work_axes]
        if not work_axes:
            raise ModelError('model: no terms for any axis of the data '
                             f'({", ".join(axes_all)})')
        if skipped:
            notes.append(f'model has no terms for {", ".join(skipped)}: skipped')
        initial = NoiseModel({a: model.terms[a] for a in work_axes}, measured.rate_hz)
        start = 'model'
        fixed = set(work_axes)
    else:
        terms = list(terms) if terms else list(DEFAULT_START)
        unknown = [t for t in terms if t not in ALL_TERMS]
        if unknown:
            raise ModelError(f'--terms: unknown term(s) {", ".join(unknown)} '
                             f'(known: {", ".join(ALL_TERMS)})')
        work_axes = axes_all
        initial = start_model(measured, work_axes, terms, alpha)
        start = 'terms:' + ','.join(terms)
        fixed = set()
    cols = [list(measured.axes).index(a) for a in work_axes]
    ys = {a: np.log(measured.adev[:, j]) for a, j in zip(work_axes, cols)}
    tau = measured.tau
    rng = np.random.default_rng(seed)
    current = {a: dict(initial.terms.get(a, {})) for a in work_axes}
    bands = _bands(current, work_axes, measured, n_sims, rng)
    gaps = {a: measure_gap(ys[a], bands[a], alpha) for a in work_axes}
    initial_gaps = dict(gaps)
    snapshots = [Snapshot({a: dict(current[a]) for a in work_axes}, bands, gaps)]
    steps = []
    open_axes = set(work_axes)
    pending = []
    for _ in range(max_steps):
        pending = []
        for axis in work_axes:
            if axis not in open_axes:
                continue
            cands, _ = evaluate_candidates(ys[axis], tau, measured.rate_hz, bands[axis],
                                           current[axis], alpha, axis in fixed, gaps[axis])
            fixed.discard(axis)
            # largest AIC gain per added parameter among the significant new effects; a pure
            # recalibration of a model file's own terms only when no new effect is needed
            winner = next((c for c in cands if c.significant and c.effect != 'recalibration'),
                          None)
            if winner is None:
                winner = next((c for c in cands if c.significant), None)
            if winner is None:
                open_axes.discard(axis)
                continue
            g = gaps[axis]
            params = (_param_report(axis, winner.effect, winner.fit)
                      if winner.effect in winner.fit.terms else
                      {t: _param_report(axis, t, winner.fit) for t in winner.fit.terms})
            shows = _effect_band(tau, bands[axis], winner.fit.terms, winner.effect,
                                 measured.rate_hz) or g.tau_range
            step = Step(axis, winner.effect, shows, g.value, math.nan, params,
                        winner.fit.terms, winner.p_value,
                        _excess_slope(tau, ys[axis], bands[axis], g.tau_range),
                        [{'effect': c.effect, 'ic': c.ic, 'aic_gain_per_parameter': c.gain,
                          'delta_q': c.delta_q,
                          'p_value': c.p_value, 'significant': c.significant}
                         for c in cands],
                        index=len([s for s in steps if s.axis == axis]) + 1,
                        excursion=g.tau_range, snapshot=len(snapshots) - 1)
            current[axis] = {t: dict(p) for t, p in winner.fit.terms.items()}
            pending.append(step)
        if not pending:
            break
        previous = {a: (snapshots[-1].terms[a], bands[a]) for a in work_axes}
        bands = _bands(current, work_axes, measured, n_sims, rng, previous)
        gaps = {a: measure_gap(ys[a], bands[a], alpha) for a in work_axes}
        for step in pending:
            step.gap_after = gaps[step.axis].value
        steps.extend(pending)
        snapshots.append(Snapshot({a: dict(current[a]) for a in work_axes}, bands, gaps))
    return DiscrepancyResult(measured, work_axes, initial, NoiseModel(current, measured.rate_hz),
                             steps, initial_gaps, gaps, snapshots, n_sims, start, notes)


def sample_rate(t):
    """Sample rate (Hz) of time stamps ``t`` (s): 1 / the median increasing difference."""
    dt = np.diff(np.asarray(t, dtype=float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        raise ValueError('time stamps do not increase: cannot find the sample rate')
    return 1.0 / float(np.median(dt))


def run_samples(samples, **kwargs):
    """:func:`run_discrepancy` on a :class:`~imu_allan.formats.samples.Samples` recording.

    The sample rate is :func:`sample_rate` of the time stamps.
    """
    return run_discrepancy(samples.data, sample_rate(samples.t), axes=samples.axes, **kwargs)


def gap_summary(model, result, alpha=ALPHA):
    """Gap per axis and the effect that fits the excess, for online monitoring.

    Parameters
    ----------
    model : NoiseModel
        The reference model (e.g. loaded from a model file).
    result : AllanResult
        The latest measured curve (batch or streaming, with ``.tau``, ``.m``, ``.adev``,
        ``.n_samples``, ``.rate_hz``, ``.axes``).
    alpha : float
        Significance level.

    Returns
    -------
    dict
        ``{axis: {'gap': float, 'effect': str or None, 'consistent': bool, 'p_value': float,
        'tau_range_s': [lo, hi] or None}}`` for the axes both the model and the result have.
        Analytic spread only (no simulation), so it costs milliseconds per axis.

    """
    out = {}
    for j, axis in enumerate(result.axes):
        axis_terms = model.terms.get(axis)
        if not axis_terms:
            continue
        ok = np.isfinite(result.adev[:, j]) & (result.adev[:, j] > 0)
        if ok.sum() < 6:
            continue
        tau, ms = result.tau[ok], np.asarray(result.m)[ok]
        y = np.log(result.adev[ok, j])
        band = model_band(axis_terms, tau, ms, int(result.n_samples), result.rate_hz)
        gap = measure_gap(y, band, alpha)
        effect = None
        if not gap.consistent:
            cands, _ = evaluate_candidates(y, tau, result.rate_hz, band, axis_terms, alpha,
                                           fixed=True, gap=gap)
            winner = next((c for c in cands if c.significant and c.effect != 'recalibration'),
                          None) or next((c for c in cands if c.significant), None)
            if winner is not None:
                effect = winner.effect
        out[axis] = {'gap': gap.value, 'effect': effect, 'consistent': gap.consistent,
                     'p_value': gap.p_value,
                     'tau_range_s': list(gap.tau_range) if gap.tau_range else None}
    return out
