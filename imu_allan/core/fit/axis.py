"""
Joint, weighted, non-negative fit of noise terms to a measured Allan variance curve, per axis.

The method is docs/method.md section 4 (model, correlation between averaging times, intervals,
term selection by chi^2 + 2 k ln T) in the log domain of section 11 (:class:`Problem`).  The
IEEE terms are linear in their squared coefficients c_j = Q^2, N^2, B^2, K^2, R^2 (shapes in
:mod:`imu_allan.core.terms`); Gauss-Markov and sinusoid are linear in sigma^2 / A^2 once
tau_c / f0 is fixed, which is profiled over a grid and refined (intervals: delta chi^2 = 1).
"""

import copy
from dataclasses import dataclass, field
from itertools import combinations
import math

import numpy as np

from .bisection import guided, halve, log_ratio, run
from .bounded_min import bounded_minimum
from .nnls import nnls_scaled
from ..allan.edf import _gammainccinv, CI_LEVEL
from ..allan.log_chi2 import log_bias, log_sd
from ..terms import sinusoid_shape, TERMS
from ..units import ALL_TERMS, IEEE_TERMS

#: Correlation width (decades) of AVAR estimates vs noise exponent alpha (measured, see doc).
CORRELATION_WIDTH = {2: 0.41, 1: 0.41, 0: 0.41, -1: 0.58, -2: 1.08}
#: Flicker noise also correlates estimates decades apart (0.06 at two decades): weight of a
#: long-range exponential component exp(-|d log10 tau| / 3) per noise exponent.
CORRELATION_TAIL = {-1: 0.1}
_MIN_EDF = 1.0


def selection_penalty(problem):
    """Return the selection criterion's charge per term on ``problem``: 2 ln T (chi^2 units)."""
    return SELECTION_PENALTY * math.log(max(problem.tau.size, 2))


def usable_points(avar, edf):
    """Return the mask of averaging times a fit can use: a finite AVAR > 0 with EDF >= 1."""
    return np.isfinite(avar) & (avar > 0) & np.isfinite(edf) & (edf >= _MIN_EDF)


#: Multiple of ln(T) charged per term in the selection criterion (BIC uses 1).  Measured on
#: 16 simulated 2-h records x 6 axes (thesis and ADIS16448-like models): 1 -> 91 of 96 axes get
#: exactly the true terms (4 spurious random walks from flicker drift), 2 -> 95 of 96.
SELECTION_PENALTY = 2.0
#: Gauss-Newton steps of a fit at most, the relative chi^2 change that ends them, and the
#: smallest step fraction tried before a step is given up.
_GN_ITERATIONS = 8
_GN_TOLERANCE = 1e-6
_MIN_STEP = 1.0 / 16.0
#: A term set whose criterion exceeds the best one's by less than this is an alternative the
#: data cannot reject (Kass & Raftery 1995: a BIC difference of 6-10 is strong evidence).
ALTERNATIVE_MARGIN = 6.0
#: Delta chi^2 of the 95 % upper limit of an undetected term (:func:`upper_limit`).
UPPER_LIMIT_DELTA_CHI2 = 4.0
_LIMIT_RESOLUTION = 1e-3  # of the upper limit in log c: 0.05 % of the coefficient


@dataclass
class AxisFit:
    """Fit of one axis: parameters, 68.3 % intervals and goodness of fit."""

    terms: dict = field(default_factory=dict)       # term -> {param: value}
    intervals: dict = field(default_factory=dict)   # term -> {param: (lo, hi)}
    chi2: float = math.nan
    dof: int = 0
    n_points: int = 0
    #: squared coefficients c_j of the selected terms and their GLS covariance (term order)
    coef: dict = field(default_factory=dict)
    cov: np.ndarray = None
    #: (criterion, term names) of every candidate term set, best first (automatic selection)
    candidates: list = field(default_factory=list)
    #: the fit of every candidate set, by its terms (frozenset): the model averaging's
    #: (:mod:`.averaging`)
    candidate_fits: dict = field(default_factory=dict)
    #: the criterion's charge per term of that selection (chi^2 units)
    selection_penalty: float = 0.0
    #: the terms that selection considered (quantization is not, beside a filter)
    considered: tuple = ()
    #: what another curve said about the open term sets (:func:`.hadamard_check.check`)
    evidence: list = field(default_factory=list)
    #: term -> its 95 % upper limit, filled on demand by ``FittedModel.upper_limit`` (kept
    #: with the fit, so a model re-wrapping these fits reuses them)
    upper_limits: dict = field(default_factory=dict)
    #: resolved term -> the lowest lower end over open sets and held terms
    #: (``FittedModel.alarm_lows``; None: not computed yet)
    alarm_lows: dict = None
    #: does the model describe the curve (:class:`.adequacy.Adequacy`; set by fit_noise_model)
    adequacy: object = None
    #: the measured curve as fitted (:class:`Problem`: span, weights, fixed line frequencies)
    problem: object = None
    #: the span's nuisance lines, fitted: frequency (Hz) -> amplitude (SI, peak)
    lines: dict = field(default_factory=dict)
    #: the filter's deficit c (SI^2): AVAR - c tau0 / tau^2, 1.5 (D / S) N^2 (:mod:`.tau_range`;
    #: fitted for a measured filter, N's for a known one)
    filter_deficit: float = 0.0
    #: on a problem with a given spread (:meth:`Problem.from_log_level`) the evidence of
    #: :func:`_sandwich_uncertainty`: Jacobian, its column ``labels`` (term, 'amp' or 'pos'),
    #: covariance of the log parameters, 95 % intervals, {term: {param: at a bound}}
    jac: np.ndarray = None
    labels: list = field(default_factory=list)
    log_cov: np.ndarray = None
    intervals95: dict = field(default_factory=dict)
    at_bound: dict = field(default_factory=dict)

    @property
    def rejected_sets(self):
        """Return the term sets (frozensets) another curve contradicts (:attr:`evidence`)."""
        return {frozenset(e['terms']) for e in self.evidence if e['rejected']}

    @property
    def tau_range(self):
        """Return the averaging times fitted, and why: the problem's span (a TauRange) or None."""
        return None if self.problem is None else self.problem.span

    @property
    def filter_moment_fitted(self):
        """Return the moment D/S the fitted filter deficit implies (c = 1.5 (D/S) N^2), or None."""
        white = self.coef.get('white_noise')
        return self.filter_deficit / (1.5 * white) if self.filter_deficit and white else None


class FitError(ValueError):
    """The curve cannot be fitted (no usable averaging times)."""


def correlation_matrix(tau, alpha, widths=None, tails=None):
    """
    Correlation of AVAR estimates between averaging times (docs/method.md section 4).

    rho_ij = (1 - c) exp(-|u_i - u_j|^1.5) + c exp(-|log10(tau_i / tau_j)| / 3), u the
    integral of d(log10 tau) / w(alpha); c enters as sqrt(c_i c_j), so the matrix stays
    positive definite.  ``widths`` w, ``tails`` c: per noise exponent, default
    :data:`CORRELATION_WIDTH` and :data:`CORRELATION_TAIL` (the Hadamard variance has its own).
    """
    widths = CORRELATION_WIDTH if widths is None else widths
    tails = CORRELATION_TAIL if tails is None else tails
    logt = np.log10(np.asarray(tau, dtype=float))
    width = np.array([widths.get(int(a), 0.5) for a in alpha])
    tail = np.sqrt([tails.get(int(a), 0.0) for a in alpha])
    steps = np.diff(logt) / (0.5 * (width[1:] + width[:-1]))
    u = np.concatenate([[0.0], np.cumsum(steps)])
    base = np.sqrt(1.0 - tail ** 2)
    short = np.exp(-np.abs(u[:, None] - u[None, :]) ** 1.5)
    long = np.exp(-np.abs(logt[:, None] - logt[None, :]) / 3.0)
    return base[:, None] * base[None, :] * short + tail[:, None] * tail[None, :] * long


class Problem:
    """
    The data of one axis in the log domain, whitened on demand for a given model curve.

    y_i = ln(estimate_i) - (psi(nu/2) - ln(nu/2)) has mean ln AVAR_i and a spread
    s_i = sqrt(psi'(nu/2)) that does not depend on the model (:mod:`..allan.log_chi2`); the fit
    minimises chi^2 = r' (S C S)^-1 r over the log residuals r = y - ln a(tau) of a model curve
    a, C the correlation (:func:`correlation_matrix`): docs/method.md section 11.  L^-1, the
    inverse Cholesky factor of C, is computed once per problem.  ``expected=True``: ``avar``
    is an expected curve (the advisor's noise-free forecasts), without the log's bias correction.
    """

    #: correlation widths and long-range shares of the estimates (:func:`correlation_matrix`)
    correlation_widths = CORRELATION_WIDTH
    correlation_tails = CORRELATION_TAIL
    #: level, spread and correlation given (:meth:`from_log_level`), not from the EDF
    spread_given = False
    #: a model part held at a fixed size (AVAR per tau, SI^2), added to every fitted curve
    offset = 0.0
    #: no filter's deficit unless the span has one (:meth:`__init__`)
    deficit_per_white = 0.0
    deficit_fitted = False

    def __init__(self, tau, avar, edf, alpha, rate_hz, duration_s=None, span=None,
                 expected=False):
        """
        Keep the usable averaging times of one axis (s, AVAR in SI units squared, EDF).

        ``duration_s`` (the record length, s) gives a rate ramp's drift variance
        (:func:`ramp_drift_variance`).  ``span`` (a :class:`.tau_range.TauRange`): keep only
        its averaging times, fix the frequency of its line (the ``sinusoid``'s) and carry its
        nuisance columns in every fit: its other lines and a measured filter's deficit
        -tau0 / tau^2 (:mod:`.tau_range`), their sizes fitted.
        """
        self.duration_s = duration_s
        tau = np.asarray(tau, dtype=float)
        ok = usable_points(avar, edf)
        if span is not None:
            ok &= (tau >= span.lo * (1.0 - 1e-9)) & (tau <= span.hi * (1.0 + 1e-9))
        self.tau = tau[ok]
        self.avar = avar[ok]
        self.edf = edf[ok]
        self.alpha = np.asarray(alpha)[ok]
        self.rate_hz = rate_hz
        self.span = span
        self.fixed = ({'sinusoid': span.line[0]} if span is not None and span.line is not None
                      else {})
        #: the span's other lines (Hz): nuisance columns per unit amplitude^2
        self.lines = tuple(f for f, _ in span.lines) if span is not None else ()
        self.filtered = bool(span is not None and span.filter_moment > 0.0)
        #: a known filter's deficit per unit N^2, 1.5 D / S, in white noise's column (0: none)
        self.deficit_per_white = span.deficit_per_white if span is not None else 0.0
        self.deficit_fitted = self.filtered and not self.deficit_per_white
        shapes = [sinusoid_shape(self.tau, f) for f in self.lines]
        if self.deficit_fitted:
            shapes.append(-1.0 / (self.rate_hz * self.tau * self.tau))
        self.nuisance = np.column_stack(shapes) if shapes else None
        self.corr = correlation_matrix(self.tau, self.alpha, self.correlation_widths,
                                       self.correlation_tails) + 1e-9 * np.eye(ok.sum())
        self._l_inv = np.tril(np.linalg.inv(np.linalg.cholesky(self.corr)))
        self._rel_sd = log_sd(self.edf)
        #: ln AVAR the estimates stand for (mean-unbiased) and its level, SI^2
        self.log_level = np.log(self.avar) - (0.0 if expected else log_bias(self.edf))
        self.level = np.exp(self.log_level)
        self._floor = 1e-3 * self.level  # the smallest model AVAR a weight or log uses
        self._columns = {}

    @classmethod
    def from_log_level(cls, tau, log_level, log_spread, corr, alpha, rate_hz):
        """
        Return a problem whose ln AVAR, spread and correlation are given (a simulated band).

        ``log_level``: ln AVAR (SI^2), bias-corrected; ``log_spread``: its standard deviation
        per tau (holding the share of any deterministic term); ``corr``: the estimates'
        correlation.  The fit is then working-independence, chi^2 = sum z^2 with
        z = (log_level - ln a) / log_spread (the discrepancy gap's metric,
        :mod:`..discrepancy.significance`); the correlation enters only the sandwich
        covariance (:func:`_sandwich_uncertainty`).
        """
        self = cls.__new__(cls)
        self.tau = np.asarray(tau, dtype=float)
        self.alpha = np.asarray(alpha)
        self.rate_hz = rate_hz
        self.duration_s = self.span = self.edf = self.nuisance = self._l_inv = None
        self.fixed, self.lines, self.filtered, self._columns = {}, (), False, {}
        self.spread_given = True
        self.corr = np.asarray(corr, dtype=float)
        self._rel_sd = np.asarray(log_spread, dtype=float)
        self.log_level = np.asarray(log_level, dtype=float)
        self.level = self.avar = np.exp(self.log_level)
        self._floor = 1e-300  # no floor: a far-off model's z grows as its log
        return self

    def with_offset(self, avar):
        """Return a copy whose model AVAR gets ``avar`` (per tau, SI^2) added: a held term."""
        other = copy.copy(self)  # shares the cache of fixed shapes
        other.offset = self.offset + np.asarray(avar, dtype=float)
        return other

    def column(self, name, position=None):
        """
        AVAR shape of a term at the averaging times (kept for terms without a position).

        White noise through a known filter carries its deficit: 1 / tau - 1.5 (D / S) tau0 /
        tau^2 (:mod:`.tau_range`).
        """
        if position is not None:
            return TERMS[name].shape(self.tau, self.rate_hz, position)
        if name not in self._columns:  # profiles and forecasts ask again for every trial
            shape = TERMS[name].shape(self.tau, self.rate_hz, None)
            if name == 'white_noise' and self.deficit_per_white:
                shape = shape - self.span.known_deficit(self.tau, self.rate_hz)
            self._columns[name] = shape
        return self._columns[name]

    def with_nuisance(self, columns):
        """``columns`` (term shapes, one column each) followed by the nuisance lines' shapes."""
        return columns if self.nuisance is None else np.column_stack([columns, self.nuisance])

    def whiten(self, model, columns, deterministic=0.0, spread=0.0):
        """
        Return ``columns`` (AVAR per tau, one column each) whitened for ``model`` AVAR.

        A column g becomes L^-1 (g / (s noise)).  ``deterministic``: the part of ``model`` from
        a rate ramp, which does not scatter the estimate (noise = model - deterministic;
        docs/method.md section 4); ``spread`` (AVAR per tau): scatter added to the chi-square
        one (:func:`ramp_cross_sd`).
        """
        # (x - 0.0 is x: the subtraction is skipped without a ramp; whiten runs in every step)
        noise = np.maximum(model if isinstance(deterministic, float) and deterministic == 0.0
                           else model - deterministic, self._floor)
        sd = self._rel_sd * noise
        if not (isinstance(spread, float) and spread == 0.0):
            sd = np.hypot(sd, spread)
        scaled = columns / sd[:, None]
        return scaled if self._l_inv is None else self._l_inv @ scaled

    def chi2(self, model, deterministic=0.0, spread=0.0):
        """Return the log-domain chi^2 of a model curve (AVAR per tau; see the class)."""
        model = np.maximum(model, self._floor)
        resid = self.whiten(model, (model * (self.log_level - np.log(model)))[:, None],
                            deterministic, spread)[:, 0]
        return float(resid @ resid)

    def solve(self, shapes, iterations=_GN_ITERATIONS, offset=0.0, deterministic=None,
              offset_deterministic=False, spread=None):
        """
        Gauss-Newton NNLS in the log domain; return (coefficients, chi2, whitened design).

        Each step is NNLS on the whitened working response a0 (1 + y - ln a0) - offset about
        the current curve a0 (first: the measured level), halved while the exact chi^2 grows.
        ``offset``: a fixed model part (AVAR per tau); ``deterministic``: the column index of a
        rate ramp in ``shapes``, ``offset_deterministic``: the offset is one (:meth:`whiten`);
        ``spread(coef)``: the extra scatter those coefficients imply.  The whitened design's
        normal matrix inverted is the coefficients' covariance.
        """
        fixed = offset if offset_deterministic else 0.0

        def curve(coef):
            model = np.maximum(shapes @ coef + offset, self._floor)
            det = fixed + (0.0 if deterministic is None
                           else shapes[:, deterministic] * coef[deterministic])
            return model, det, 0.0 if spread is None else spread(coef)
        model, det, extra = self.level, fixed, 0.0
        coef, chi2 = None, math.inf
        for _ in range(iterations):
            work = model * (1.0 + self.log_level - np.log(model)) - offset
            low = self.whiten(model, np.column_stack([shapes, work]), det, extra)
            new = nnls_scaled(low[:, :-1], low[:, -1])
            step = 1.0
            while True:
                trial = new if coef is None else coef + step * (new - coef)
                trial_curve = curve(trial)
                trial_chi2 = self.chi2(*trial_curve)
                if trial_chi2 <= chi2 or step < _MIN_STEP:
                    break
                step *= 0.5
            done = chi2 - trial_chi2 < _GN_TOLERANCE * (1.0 + trial_chi2)
            if trial_chi2 <= chi2 or coef is None:
                coef, chi2, (model, det, extra) = trial, trial_chi2, trial_curve
            if done:
                break
        return coef, chi2, self.whiten(model, shapes, det, extra)


def shape_columns(problem, names, nonlinear):
    """AVAR shape of each named term at the problem's averaging times, one column each."""
    return np.column_stack([problem.column(name, nonlinear.get(name)) for name in names])


def deterministic_index(names):
    """Index of the deterministic term (rate ramp) in ``names``, None if there is none."""
    names = list(names)
    return names.index('rate_ramp') if 'rate_ramp' in names else None


def ramp_drift_variance(problem, coef):
    """
    Return the variance of a fitted rate ramp's R^2 from the noise's own drift over the record.

    4 R^2 Var(D) / (T - 2 w)^2, D the difference of the noise's averages over windows
    w = tau_max at the record's two ends (:func:`drift_structure`; docs/method.md section 4);
    0 without a record length.  ``coef``: squared coefficients by term.
    """
    t_rec = problem.duration_s
    if not t_rec or 'rate_ramp' not in coef:
        return 0.0
    w = float(problem.tau[-1])
    span = max(t_rec - 2.0 * w, w)
    return 4.0 * coef['rate_ramp'] * drift_structure(coef, t_rec, w) / span ** 2


def ramp_cross_sd(problem, coef):
    """
    Return the sd (AVAR units, per tau) of a ramp's cross term with the noise's drift.

    sqrt(R^2) tau^2 / (T - 2 tau) sd(D), D the noise's drift at windows tau
    (:func:`drift_structure`), taken as independent scatter (docs/method.md section 11).
    ``coef``: squared coefficients by term.
    """
    r2 = coef.get('rate_ramp', 0.0)
    t_rec = problem.duration_s
    if not (r2 > 0 and t_rec):
        return 0.0
    tau = problem.tau
    drift = tau * tau / np.maximum(t_rec - 2.0 * tau, tau)
    return math.sqrt(r2) * drift * np.sqrt(drift_structure(coef, t_rec, tau))


def drift_structure(coef, t_rec, w):
    """
    Var(D): the difference of the noise's averages over windows ``w`` (s) ``t_rec`` apart.

    The structure function of docs/method.md section 4 (``coef``: squared coefficients):
    2 N^2 / w + (2 B^2 / pi) (ln(T / w) + 1.5) + K^2 T + 4 Q^2 / w^2; ``w`` may be an array.
    """
    w = np.asarray(w, dtype=float)
    return (2.0 * coef.get('white_noise', 0.0) / w
            + 2.0 / math.pi * coef.get('bias_instability', 0.0)
            * (np.log(np.maximum(t_rec / w, 1.0)) + 1.5)
            + coef.get('rate_random_walk', 0.0) * t_rec
            + 4.0 * coef.get('quantization', 0.0) / w ** 2)


def _log_range(problem, name, ranges=None):
    """Log-position range of a free hump term: ``ranges[name]`` or its peak inside the span."""
    lo, hi = (ranges[name] if ranges and name in ranges
              else TERMS[name].position_range(problem.tau[0], problem.tau[-1]))
    return math.log(lo), math.log(hi)


def fit_terms(problem, names, profile_intervals=True, fixed=None, ranges=None, init=None,
              hints=None):
    """
    Fit the named terms on ``problem``; return an :class:`AxisFit` (keeping the problem).

    ``profile_intervals=False`` leaves the intervals of tau_c / f0 NaN (their bisection is
    most of the cost; criteria need none).  Positions (tau_c s, frequency_hz Hz): ``fixed``
    ({term: position}) holds those besides the problem's own line; ``ranges`` ({term: (lo,
    hi)}) replaces a free one's default range; ``init`` (a previous fit's {term: params}) and
    ``hints`` ({term: position}) add points to its profile's grid (:func:`_profile_positions`).
    A problem with a given spread gets the sandwich uncertainty (:func:`_sandwich_uncertainty`).
    """
    names = list(names)
    held = {**problem.fixed, **(fixed or {})}
    nonlinear = {n: held[n] for n in names if n in held}
    nl_names = [n for n in names if TERMS[n].position and n not in nonlinear]

    # a given spread already holds a deterministic term's share (no ramp weighting)
    ramp = None if problem.spread_given else deterministic_index(names)

    def cross(coef):  # a ramp's cross term with the noise's drift, as scatter
        return ramp_cross_sd(problem, dict(zip(names, coef[:len(names)])))
    spread = cross if ramp is not None and problem.duration_s else None

    def evaluate(nonlinear):
        return problem.solve(problem.with_nuisance(shape_columns(problem, names, nonlinear)),
                             offset=problem.offset, deterministic=ramp, spread=spread)

    starts = {t: TERMS[t].unpack(p)[1] for t, p in (init or {}).items()
              if t in nl_names}
    profiles = _profile_positions(problem, nl_names, nonlinear, evaluate, ranges, starts,
                                  hints or {})
    coef, chi2, g = evaluate(nonlinear)
    fit = AxisFit(chi2=chi2, n_points=problem.tau.size, problem=problem)
    coef, extra = coef[:len(names)], coef[len(names):]
    fit.lines = {f: math.sqrt(c) for f, c in zip(problem.lines, extra) if c > 0}
    fit.filter_deficit = (float(extra[-1]) if problem.deficit_fitted else
                          problem.deficit_per_white * float(coef[names.index('white_noise')])
                          if problem.deficit_per_white and 'white_noise' in names else 0.0)
    used = np.concatenate([coef > 0, extra > 0])  # the nuisance columns count for the covariance
    if problem.spread_given:
        _sandwich_uncertainty(fit, names, nonlinear, nl_names, coef, ranges)
    else:
        _gls_uncertainty(fit, names, nonlinear, coef, g, used,
                         profiles if profile_intervals else None)
    n_params = int(used.sum()) + sum(1 for n in nl_names if coef[names.index(n)] > 0)
    fit.dof = max(problem.tau.size - n_params, 0)
    return fit


def _profile_positions(problem, free, nonlinear, evaluate, ranges, starts, hints):
    """
    Profile the position of each ``free`` hump term in turn; set it in ``nonlinear``.

    A grid of 25 over the log range (plus the ``hints`` and ``starts`` positions), then a
    bounded minimum between the best point's neighbours.  A hump not yet profiled is held at
    its start (default mid-range); those with a start go last, so a new hump is placed beside
    the ones a previous fit placed.  ``evaluate(positions)``: the fit at given positions.
    Returns {term: (grid, chi^2 per point, ln position, chi^2 as a function of ln position)}.
    """
    held = {}
    for name in free:
        lo, hi = _log_range(problem, name, ranges)
        start = starts.get(name)
        held[name] = (start if start is not None and lo <= math.log(start) <= hi
                      else math.exp(np.mean((lo, hi))))
    profiles = {}
    for name in sorted(free, key=lambda n: n in starts):  # (stable: given order otherwise)
        lo, hi = _log_range(problem, name, ranges)
        grid = np.linspace(lo, hi, 25)
        extra = [math.log(p) for p in (hints.get(name), starts.get(name))
                 if p is not None and lo <= math.log(p) <= hi]
        if extra:
            grid = np.unique(np.concatenate([grid, extra]))

        def chi2_at(logp, name=name):
            return evaluate({**held, **nonlinear, name: math.exp(logp)})[1]
        values = np.array([chi2_at(v) for v in grid])
        k = int(np.argmin(values))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        best = bounded_minimum(chi2_at, a, b, xatol=1e-3) if b > a else None
        logp = best[0] if best is not None and best[1] <= values[k] else grid[k]
        nonlinear[name] = math.exp(logp)
        profiles[name] = (grid, values, logp, chi2_at)
    return profiles


def _gls_uncertainty(fit, names, nonlinear, coef, g, used, profiles):
    """
    Fill ``fit``'s terms, coefficients, GLS covariance and 68.3 % intervals.

    ``g``: the whitened design at the solution (nuisance columns last), ``used`` its columns
    with a non-zero coefficient; ``profiles``: :func:`_profile_positions`' (None: position
    intervals NaN).  A term pinned at zero is left out.
    """
    problem = fit.problem
    active = coef > 0
    try:  # (the terms come first: their block of the inverse is their marginal covariance)
        cov = np.linalg.inv(g[:, used].T @ g[:, used])[:active.sum(), :active.sum()]
    except np.linalg.LinAlgError:
        cov = np.full((active.sum(), active.sum()), np.nan)
    sd = np.full(coef.size, np.nan)
    sd[active] = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    fit.coef = {name: float(c) for name, c in zip(names, coef) if c > 0}
    if 'rate_ramp' in fit.coef:
        j = list(fit.coef).index('rate_ramp')
        cov = cov.copy()
        cov[j, j] += ramp_drift_variance(problem, fit.coef)
        sd[names.index('rate_ramp')] = math.sqrt(max(cov[j, j], 0.0))
    fit.cov = cov
    for j, name in enumerate(names):
        if not active[j]:
            continue
        value = math.sqrt(coef[j])
        interval = coefficient_interval(coef[j], sd[j] ** 2, CI_LEVEL, name == 'rate_ramp')
        spec = TERMS[name]
        fit.terms[name] = spec.pack(value, nonlinear.get(name))
        position = None
        if name in problem.fixed:  # known from elsewhere (a line's frequency): no interval
            position = (nonlinear[name],) * 2
        elif spec.position:
            position = (_profile_interval(profiles[name], fit.chi2) if profiles is not None
                        else (math.nan, math.nan))
        fit.intervals[name] = spec.pack(interval, position)


def _sandwich_uncertainty(fit, names, nonlinear, free, coef, ranges):
    """
    Fill ``fit``'s terms and evidence on a problem with a given spread (working independence).

    The Jacobian J of z (per squared coefficient, then per ln position of each ``free`` hump;
    unit-norm columns) and the sandwich covariance (J'J)^-1 J'RJ (J'J)^-1 under the estimates'
    correlation R, mapped to ln amplitude and ln position: 68.3 and 95 % intervals
    exp(ln value -+ z sd).  Every named term is kept, one pinned at zero too (for
    :mod:`..discrepancy.significance`): infinite log variance, at its bound, as is a free
    position within 1 % of its log range's ends.
    """
    problem = fit.problem
    shapes = shape_columns(problem, names, nonlinear)
    model = np.maximum(shapes @ coef + problem.offset, problem._floor)
    step = 1e-5  # (ln position) of the central difference of a hump's shape
    moves = [coef[names.index(t)] * (problem.column(t, nonlinear[t] * math.exp(step))
                                     - problem.column(t, nonlinear[t] * math.exp(-step)))
             / (2.0 * step) for t in free]
    jac = -problem.whiten(model, np.column_stack([shapes] + moves))
    norm = np.linalg.norm(jac, axis=0)
    norm[norm == 0.0] = 1.0
    fit.jac = jac / norm
    fit.labels = [(t, 'amp') for t in names] + [(t, 'pos') for t in free]
    inv = np.linalg.pinv(fit.jac.T @ fit.jac)
    with np.errstate(over='ignore', invalid='ignore'):
        cov = inv @ (fit.jac.T @ problem.corr @ fit.jac) @ inv / np.outer(norm, norm)
    active = coef > 0
    fit.coef = {t: float(c) for t, c in zip(names, coef) if c > 0}
    fit.cov = cov[:len(names), :len(names)][np.ix_(active, active)]
    pinned = np.array([not active[names.index(t)] for t, _ in fit.labels])
    scale = np.concatenate([2.0 * coef, np.ones(len(free))])  # d c = 2 c d ln amplitude
    scale[pinned] = 1.0
    fit.log_cov = cov / np.outer(scale, scale)
    fit.log_cov[pinned, :] = fit.log_cov[:, pinned] = math.inf
    with np.errstate(divide='ignore'):
        theta = np.concatenate([0.5 * np.log(coef), np.log([nonlinear[t] for t in free])])
    for t in names:
        fit.terms[t] = TERMS[t].pack(math.sqrt(coef[names.index(t)]), nonlinear.get(t))
        if t in nonlinear and t not in free:  # a held position: a point, not at a bound
            pname = TERMS[t].params[1]
            for table in (fit.intervals, fit.intervals95):
                table.setdefault(t, {})[pname] = (nonlinear[t],) * 2
            fit.at_bound.setdefault(t, {})[pname] = False
    z95 = two_sided_z(0.95)
    for i, (t, kind) in enumerate(fit.labels):
        pname = TERMS[t].params[0 if kind == 'amp' else 1]
        var = fit.log_cov[i, i]
        sd = math.sqrt(max(var, 0.0)) if np.isfinite(var) else math.inf
        fit.intervals.setdefault(t, {})[pname] = _log_interval(theta[i], sd)
        fit.intervals95.setdefault(t, {})[pname] = _log_interval(theta[i], z95 * sd)
        edge = False
        if kind == 'pos':
            lo, hi = _log_range(problem, t, ranges)
            edge = min(theta[i] - lo, hi - theta[i]) < 1e-2 * (hi - lo)
        fit.at_bound.setdefault(t, {})[pname] = bool(pinned[i] or edge)


def _log_interval(log_value, half_width):
    """Interval exp(log_value -+ half_width), clipped to the float range (0 .. 1e300)."""
    if not math.isfinite(half_width):
        return 0.0, math.inf
    lo = math.exp(max(log_value - half_width, -700.0))
    hi = math.exp(min(log_value + half_width, 690.0))
    return float(lo), float(hi)


def _profile_interval(profile, chi2_min):
    """Delta chi^2 = 1 interval of a profiled log-parameter (bounded by the grid)."""
    grid, _, logp, chi2_at = profile

    def crossing(edge):
        if abs(chi2_at(edge) - chi2_min) < 1.0:
            return edge
        a, b = sorted((logp, edge))  # bisection on the monotone side of the minimum
        return halve(lambda x: (x > logp) == (chi2_at(x) - chi2_min < 1.0), a, b, 30)
    return math.exp(crossing(grid[0])), math.exp(crossing(grid[-1]))


def fit_axis(tau, avar, edf, alpha, rate_hz, terms=None, duration_s=None, span=None):
    """
    Fit one axis; ``terms=None`` selects the IEEE terms (chi^2 + 2 k ln T, module docstring).

    ``duration_s`` and ``span``: see :class:`Problem`; every candidate set also holds the
    span's line.  The returned fit keeps its problem (``fit.problem``).
    """
    problem = Problem(np.asarray(tau, float), np.asarray(avar, float),
                      np.asarray(edf, float), np.asarray(alpha), rate_hz, duration_s, span)
    if problem.tau.size == 0:
        raise FitError('no averaging time with a usable Allan variance')
    if terms is not None:
        unknown = [t for t in terms if t not in ALL_TERMS]
        if unknown:
            raise ValueError(f'unknown noise term(s): {", ".join(unknown)}')
        return fit_terms(problem, terms)
    # White noise is in every set (docs/method.md section 11); quantization is in none beside
    # a filter's deficit or a resonance's tail, which have its 1/tau^2 shape (section 10).
    base = tuple(problem.fixed) + ('white_noise',)
    candidates = [t for t in IEEE_TERMS if t != 'white_noise'] if problem.tau.size >= 4 else []
    if candidates and (problem.filtered or (span is not None
                                            and span.limited_by == 'resonance')):
        candidates.remove('quantization')
    best, best_bic = None, math.inf
    penalty = selection_penalty(problem)
    scored, fits = [], {}
    for k in range(0, len(candidates) + 1):
        for subset in combinations(candidates, k):
            fit = fit_terms(problem, base + subset)
            if not set(subset) <= set(fit.terms):  # a term pinned at zero: a smaller set has it
                continue
            bic = fit.chi2 + len(fit.terms) * penalty
            scored.append((bic, base + subset))
            fits[frozenset(base + subset)] = fit
            if bic < best_bic:
                best, best_bic = fit, bic
    if best is None:
        return AxisFit(n_points=problem.tau.size, problem=problem)
    best.candidates = sorted(scored, key=lambda item: item[0])
    best.candidate_fits = fits
    best.selection_penalty = penalty
    best.considered = base + tuple(candidates)
    return best


def widen(fit, scale):
    """
    Widen every interval of ``fit`` by ``scale`` (in place): its covariance by scale^2.

    For a fit the adequacy test rejects (:attr:`.adequacy.Adequacy.scale`); positions (tau_c,
    f0) by their log half-widths times ``scale``, a fixed position stays a point.
    """
    if not scale > 1.0 or fit.cov is None:
        return
    fit.cov = fit.cov * scale * scale
    for j, name in enumerate(fit.coef):
        spec = TERMS[name]
        interval = coefficient_interval(fit.coef[name], max(fit.cov[j, j], 0.0), CI_LEVEL,
                                        name == 'rate_ramp')
        position = None
        if spec.position:
            value = fit.terms[name][spec.position]
            lo, hi = fit.intervals[name][spec.position]
            position = ((lo, hi) if not (lo > 0 and hi > 0) else
                        (value * (lo / value) ** scale, value * (hi / value) ** scale))
        fit.intervals[name] = spec.pack(interval, position)


def upper_limit(tau, avar, edf, alpha, rate_hz, terms, term, delta_chi2=UPPER_LIMIT_DELTA_CHI2):
    """
    Largest coefficient of an undetected ``term`` the data allow (profile likelihood, SI).

    The other ``terms`` are refitted for each trial value; the limit is where chi^2 exceeds
    its minimum by ``delta_chi2`` (4: two-sided 95 %), above the best-fitting coefficient
    (docs/method.md section 7).  Returns NaN if not bounded.
    """
    problem = Problem(np.asarray(tau, float), np.asarray(avar, float), np.asarray(edf, float),
                      np.asarray(alpha), rate_hz)
    return problem_upper_limit(problem, terms, term, delta_chi2)


def problem_upper_limit(problem, terms, term, delta_chi2=UPPER_LIMIT_DELTA_CHI2):
    """:func:`upper_limit` on a :class:`Problem` (its span and fixed lines: a fit's own)."""
    others = [t for t in terms if t != term and (t in IEEE_TERMS or t in problem.fixed)]
    if problem.tau.size < 2 or not others:
        return math.nan
    base = problem.with_nuisance(shape_columns(problem, others, problem.fixed))
    extra = problem.column(term)

    ramp = deterministic_index(others)

    def chi2(log_c):
        return problem.solve(base, offset=math.exp(log_c) * extra, deterministic=ramp,
                             offset_deterministic=term == 'rate_ramp')[1]

    def evaluate(log_c):  # (beyond the limit, level): the level ~ linear in log c
        excess = chi2(log_c) - chi2_min
        # (the floor keeps a level where re-weighting leaves the excess at or below 0)
        return excess > delta_chi2, log_ratio(max(excess, 1e-3 * delta_chi2), delta_chi2)

    coef, chi2_min, g = problem.solve(np.column_stack([base, extra]),
                                      deterministic=deterministic_index(others + [term]))
    hi = math.log(float(np.max(problem.avar / extra)))
    if not evaluate(hi)[0]:
        return math.nan
    # above the best-fitting coefficient the excess only grows (convex in c); below it, the
    # excess can pass delta as well, and that crossing is not the limit
    lo = max(hi - 60.0, math.log(coef[-1])) if coef[-1] > 0 else hi - 60.0
    halvings = max(math.ceil(math.log2((hi - lo) / _LIMIT_RESOLUTION)), 0)
    # first guess c + sqrt(delta) sd(c) (the linear problem's limit); near it the excess
    # grows about as c^2: slope 2 in log c
    sd = math.sqrt(max(float(np.linalg.pinv(g.T @ g)[-1, -1]), 0.0))
    guess = math.log(max(coef[-1] + math.sqrt(delta_chi2) * sd, math.exp(lo)))
    lo, _ = run(guided(evaluate, lo, hi, halvings, (2.0 * (lo - guess), 2.0 * (hi - guess))))
    return math.sqrt(math.exp(lo))


def coefficient_interval(c, var, level=CI_LEVEL, deterministic=False):
    """
    Two-sided ``level`` interval ``(lo, hi)`` of sqrt(c), c a squared coefficient of ``var``.

    c nu / chi^2_nu quantiles with Satterthwaite's nu = 2 c^2 / var (SP1065 eq. 45,
    docs/method.md section 4); the normal c +- z sd for a ``deterministic`` term (the rate
    ramp) and where :func:`chi_square_applies` says no.
    """
    if not (var > 0 and c > 0):
        return (math.sqrt(max(c, 0.0)),) * 2
    c, var = float(c), float(var)
    if deterministic or not chi_square_applies(c, var, level):
        z = two_sided_z(level)
        sd = math.sqrt(var)
        return math.sqrt(max(c - z * sd, 0.0)), math.sqrt(c + z * sd)
    nu = 2.0 * c * c / var
    low_q, high_q = _chi2_quantiles(nu, level)
    return math.sqrt(c * nu / low_q), math.sqrt(c * nu / high_q)


def _chi2_quantiles(nu, level):
    """Chi-square(nu) quantiles with upper tails p and 1 - p, p = (1 - level) / 2."""
    p = 0.5 * (1.0 - level)
    # quantile with upper tail q: 2 Q^-1(nu / 2, q) (scipy's chdtri(nu, q))
    return (2.0 * float(_gammainccinv(0.5 * nu, p)),
            2.0 * float(_gammainccinv(0.5 * nu, 1.0 - p)))


def chi_square_applies(c, var, level):
    """
    Return whether c nu / chi^2_nu gives a usable ``level`` interval (c > 0, var > 0).

    A term with sd >> c (nu below 1) has a chi-square so skewed that its upper quantile
    can lie below nu (the interval would exclude c), its lower one underflow or the upper
    bound reach 10^15 c (a random walk the Hadamard fit barely sees, nu = 0.1): there the
    normal interval is the honest statement.
    """
    nu = 2.0 * c * c / var
    if nu < 1.0:
        return False
    low_q, high_q = _chi2_quantiles(nu, level)
    return bool(low_q > nu and high_q > 0.0 and c * nu / high_q < 1e300)


def two_sided_z(level):
    """
    Return z with P(|Z| < z) = ``level`` for a standard normal Z: Phi^-1((1 + level) / 2).

    z^2 is the chi-square(1) quantile with upper tail 1 - level (no scipy.special import).
    """
    return math.sqrt(2.0 * float(_gammainccinv(0.5, 1.0 - level)))
