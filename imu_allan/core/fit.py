"""
Joint, weighted, non-negative fit of noise terms to a measured Allan variance curve.

Method (per axis)
-----------------
* The model is AVAR(tau) = sum_j c_j g_j(tau): the five IEEE terms are linear in their squared
  coefficients c_j = Q^2, N^2, B^2, K^2, R^2 (shapes in :mod:`imu_allan.core.terms`);
  Gauss-Markov and sinusoid are linear in sigma^2 / A^2 once tau_c / f0 is fixed, which is
  profiled over a grid and refined.
* Generalised least squares with c_j >= 0 (NNLS on the whitened problem).  The covariance of
  the AVAR estimates is V_i = 2 AVAR_i^2 / EDF_i on the diagonal (chi-square), with the
  correlation between averaging times measured on simulated data:
  rho_ij = (1 - c) exp(-(|u_i - u_j|)^1.5) + c exp(-|log10(tau_i / tau_j)| / 3), with
  u = integral of d(log10 tau) / w(alpha), w = 0.41 decades for white / quantization noise,
  0.58 for flicker, 1.08 for random walk, and the long-range share c = 0.1 for flicker, 0
  otherwise (c enters as sqrt(c_i c_j), so the matrix stays positive definite).  Ignoring
  this correlation (plain weighted LS) makes the intervals about twice too narrow.
* The weights use the model AVAR, not the measured one (iteratively re-weighted), so noisy low
  points do not pull the fit down.
* Intervals: 68.3 % from the GLS covariance of c_j, mapped through sqrt; for tau_c and f0 from
  the profile chi-square (delta chi^2 = 1).
* Term selection when none are asked for: every subset of the five IEEE terms is fitted and the
  one with the lowest chi^2 + 2 k ln(T) wins (k = terms with a non-zero coefficient; a BIC
  with a doubled penalty, because long-tau estimates have few degrees of freedom and flicker
  drift mimics a random walk or ramp there), so a term is only reported when the data support
  it.
"""

from dataclasses import dataclass, field
from itertools import combinations
import math

import numpy as np

from . import terms as _terms
from .bisection import guided, log_ratio, run
from .bounded_min import bounded_minimum
from .edf import _gammainccinv, CI_LEVEL
from .model import NoiseModel
from .nnls import nnls_scaled
from .terms import TERMS
from .units import ALL_TERMS, conventional, IEEE_TERMS, si_unit

#: Correlation width (decades) of AVAR estimates vs noise exponent alpha (measured, see doc).
CORRELATION_WIDTH = {2: 0.41, 1: 0.41, 0: 0.41, -1: 0.58, -2: 1.08}
#: Flicker noise also correlates estimates decades apart (0.06 at two decades): weight of a
#: long-range exponential component exp(-|d log10 tau| / 3) per noise exponent.
CORRELATION_TAIL = {-1: 0.1}
_MIN_EDF = 1.0
#: Multiple of ln(T) charged per term in the selection criterion (BIC uses 1).  Measured on
#: 16 simulated 2-h records x 6 axes (thesis and ADIS16448-like models): 1 -> 91 of 96 axes get
#: exactly the true terms (4 spurious random walks from flicker drift), 2 -> 95 of 96.
SELECTION_PENALTY = 2.0
_IRLS_ITERATIONS = 6
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
    #: what another curve said about the open term sets (:func:`.hadamard_check.check`)
    evidence: list = field(default_factory=list)


class FitError(ValueError):
    """The curve cannot be fitted (no usable averaging times)."""


def correlation_matrix(tau, alpha, widths=None, tails=None):
    """
    Correlation of AVAR estimates between averaging times (see module docstring).

    ``widths``, ``tails``: per noise exponent, default :data:`CORRELATION_WIDTH` and
    :data:`CORRELATION_TAIL` (another variance has its own, e.g. the Hadamard one).
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
    The data of one axis, whitened on demand for a given model curve.

    The covariance of the AVAR estimates for a model curve a(tau) is S C S with C the
    correlation matrix and S = diag(sqrt(2 / EDF) a).  Its Cholesky factor is S L with L the
    factor of C, so whitening by any model curve is L^-1 S^-1: L^-1 is computed once per
    problem, and each IRLS step is one small matrix product instead of a factorisation.
    """

    #: correlation widths and long-range shares of the estimates (:func:`correlation_matrix`)
    correlation_widths = CORRELATION_WIDTH
    correlation_tails = CORRELATION_TAIL

    def __init__(self, tau, avar, edf, alpha, rate_hz, duration_s=None):
        """
        Keep the usable averaging times of one axis (s, AVAR in SI units squared, EDF).

        ``duration_s`` (the record length) gives a rate ramp's drift variance
        (:func:`ramp_drift_variance`); without it a ramp's interval lacks that part.
        """
        self.duration_s = duration_s
        ok = np.isfinite(avar) & (avar > 0) & np.isfinite(edf) & (edf >= _MIN_EDF)
        self.tau = tau[ok]
        self.avar = avar[ok]
        self.edf = edf[ok]
        self.rate_hz = rate_hz
        corr = correlation_matrix(self.tau, alpha[ok], self.correlation_widths,
                                  self.correlation_tails) + 1e-9 * np.eye(ok.sum())
        self._l_inv = np.tril(np.linalg.inv(np.linalg.cholesky(corr)))
        self._rel_sd = np.sqrt(2.0 / self.edf)
        self._floor = 1e-3 * self.avar  # the smallest noise AVAR a weight uses (whiten)
        self._columns = {}

    def column(self, name, position=None):
        """AVAR shape of a term at the averaging times (kept for terms without a position)."""
        if position is not None:
            return TERMS[name].shape(self.tau, self.rate_hz, position)
        if name not in self._columns:  # profiles and forecasts ask again for every trial
            self._columns[name] = TERMS[name].shape(self.tau, self.rate_hz, None)
        return self._columns[name]

    def whiten(self, model, columns, deterministic=0.0):
        """
        Return ``columns`` (AVAR per tau, one column each) whitened for ``model`` AVAR.

        ``deterministic`` is the part of ``model`` from a deterministic signal (a rate ramp):
        it adds to the expected AVAR but not to the scatter of its estimate, whose chi-square
        variance 2 AVAR^2 / EDF belongs to the noise part alone.
        """
        # (x - 0.0 is x: the subtraction is skipped without a ramp; whiten runs in every step)
        noise = np.maximum(model if isinstance(deterministic, float) and deterministic == 0.0
                           else model - deterministic, self._floor)
        return self._l_inv @ (columns / (self._rel_sd * noise)[:, None])

    def solve(self, shapes, iterations=_IRLS_ITERATIONS, offset=0.0, deterministic=None,
              offset_deterministic=False):
        """
        IRLS GLS-NNLS; return (coefficients, chi2, whitened design).

        ``offset`` is a fixed model part (AVAR per tau) added to ``shapes @ coef``;
        ``deterministic`` the column index of a deterministic term (rate ramp) in ``shapes``,
        ``offset_deterministic`` whether the offset is one (see :meth:`whiten`).
        """
        model = self.avar
        det = 0.0
        coef = np.zeros(shapes.shape[1])
        design = np.column_stack([shapes, self.avar - offset])
        fixed = offset if offset_deterministic else 0.0
        for _ in range(iterations):
            low = self.whiten(model, design, det)
            coef = nnls_scaled(low[:, :-1], low[:, -1])
            # keep weights finite where the model vanishes (e.g. a term pinned at zero)
            model = np.maximum(shapes @ coef + offset, 1e-3 * self.avar)
            det = fixed + (0.0 if deterministic is None
                           else shapes[:, deterministic] * coef[deterministic])
        low = self.whiten(model, design, det)
        g, y = low[:, :-1], low[:, -1]
        resid = y - g @ coef
        return coef, float(resid @ resid), g


def shape_columns(problem, names, nonlinear):
    """AVAR shape of each named term at the problem's averaging times, one column each."""
    return np.column_stack([problem.column(name, nonlinear.get(name)) for name in names])


def deterministic_index(names):
    """Index of the deterministic term (rate ramp) in ``names``, None if there is none."""
    names = list(names)
    return names.index('rate_ramp') if 'rate_ramp' in names else None


def ramp_drift_variance(problem, coef):
    """
    Variance of a fitted rate ramp's R^2 from the noise's own drift over the record.

    A deterministic ramp adds R^2 tau^2 / 2 to AVAR exactly, but the cross term R tau e of
    the estimator (e the mean first difference of tau-averages, which telescopes to the
    difference D of the averages at the record's two ends over M tau0 ~ T) moves R^2 by
    2 R D / T at every tau alike: the slope the noise itself shows.  Var(D) is the noise's
    structure function at separation T with windows w = tau_max: 2 N^2 / w (white),
    (2 B^2 / pi) (ln(T / w) + 1.5) (flicker; the integral of (1 - cos 2 pi f T) sinc^2 / f,
    evaluated numerically), K^2 T (random walk), 4 Q^2 / w^2 (quantization).  Returns
    4 R^2 Var(D) / (T - 2 w)^2 (0 without a record length).
    """
    t_rec = problem.duration_s
    if not t_rec or 'rate_ramp' not in coef:
        return 0.0
    w = float(problem.tau[-1])
    span = max(t_rec - 2.0 * w, w)
    var_d = (2.0 * coef.get('white_noise', 0.0) / w
             + 2.0 / math.pi * coef.get('bias_instability', 0.0)
             * (math.log(max(t_rec / w, 1.0)) + 1.5)
             + coef.get('rate_random_walk', 0.0) * t_rec
             + 4.0 * coef.get('quantization', 0.0) / w ** 2)
    return 4.0 * coef['rate_ramp'] * var_d / span ** 2


def _nonlinear_range(problem, name):
    """Log-position range of a hump term whose peak lies inside the measured span."""
    lo, hi = TERMS[name].position_range(problem.tau[0], problem.tau[-1])
    return math.log(lo), math.log(hi)


def fit_terms(problem, names, profile_intervals=True):
    """
    Fit the named terms; return an :class:`AxisFit` (profiling tau_c / f0 when present).

    ``profile_intervals=False`` leaves the intervals of tau_c / f0 NaN: their profile
    bisection is most of the cost of such a fit, and a caller comparing criteria (the
    recording advisor) does not need them.
    """
    names = list(names)
    nl_names = [n for n in names if TERMS[n].position]

    ramp = deterministic_index(names)

    def evaluate(nonlinear):
        return problem.solve(shape_columns(problem, names, nonlinear), deterministic=ramp)

    nonlinear = {}
    profiles = {}
    for name in nl_names:  # profile each nonlinear parameter with the others held
        lo, hi = _nonlinear_range(problem, name)
        grid = np.linspace(lo, hi, 25)

        def chi2_at(logp, name=name):
            trial = {**nonlinear, name: math.exp(logp)}
            for other in nl_names:
                trial.setdefault(other, math.exp(np.mean(_nonlinear_range(problem, other))))
            return evaluate(trial)[1]
        values = np.array([chi2_at(v) for v in grid])
        k = int(np.argmin(values))
        a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
        best = bounded_minimum(chi2_at, a, b, xatol=1e-3) if b > a else None
        logp = best[0] if best is not None and best[1] <= values[k] else grid[k]
        nonlinear[name] = math.exp(logp)
        profiles[name] = (grid, values, logp, chi2_at)
    coef, chi2, g = evaluate(nonlinear)
    fit = AxisFit(chi2=chi2, n_points=problem.tau.size)
    active = coef > 0
    try:
        cov = np.linalg.inv(g[:, active].T @ g[:, active])
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
        if spec.position:
            position = (_profile_interval(profiles[name], chi2) if profile_intervals
                        else (math.nan, math.nan))
        fit.intervals[name] = spec.pack(interval, position)
    n_params = int(active.sum()) + sum(1 for n in nl_names if n in fit.terms)
    fit.dof = max(problem.tau.size - n_params, 0)
    return fit


def _profile_interval(profile, chi2_min):
    """Delta chi^2 = 1 interval of a profiled log-parameter (bounded by the grid)."""
    grid, _, logp, chi2_at = profile

    def crossing(edge):
        if abs(chi2_at(edge) - chi2_min) < 1.0:
            return edge
        a, b = sorted((logp, edge))
        for _ in range(30):  # bisection on the monotone side of the minimum
            mid = 0.5 * (a + b)
            inside = chi2_at(mid) - chi2_min < 1.0
            if (mid > logp) == inside:
                a = mid
            else:
                b = mid
        return 0.5 * (a + b)
    return math.exp(crossing(grid[0])), math.exp(crossing(grid[-1]))


def fit_axis(tau, avar, edf, alpha, rate_hz, terms=None, duration_s=None):
    """Fit one axis; ``terms=None`` selects the IEEE terms by BIC (``duration_s``: Problem)."""
    problem = Problem(np.asarray(tau, float), np.asarray(avar, float),
                      np.asarray(edf, float), np.asarray(alpha), rate_hz, duration_s)
    if problem.tau.size == 0:
        raise FitError('no averaging time with a usable Allan variance')
    if terms is not None:
        unknown = [t for t in terms if t not in ALL_TERMS]
        if unknown:
            raise ValueError(f'unknown noise term(s): {", ".join(unknown)}')
        return fit_terms(problem, terms)
    candidates = list(IEEE_TERMS) if problem.tau.size >= 4 else ['white_noise']
    best, best_bic = None, math.inf
    penalty = SELECTION_PENALTY * math.log(max(problem.tau.size, 2))
    scored = []
    for k in range(1, len(candidates) + 1):
        for subset in combinations(candidates, k):
            fit = fit_terms(problem, subset)
            if len(fit.terms) < k:  # a pinned-at-zero term: the smaller subset covers it
                continue
            bic = fit.chi2 + len(fit.terms) * penalty
            scored.append((bic, subset))
            if bic < best_bic:
                best, best_bic = fit, bic
    if best is None:
        return AxisFit(n_points=problem.tau.size)
    best.candidates = sorted(scored, key=lambda item: item[0])
    return best


def upper_limit(tau, avar, edf, alpha, rate_hz, terms, term, delta_chi2=UPPER_LIMIT_DELTA_CHI2):
    """
    Largest coefficient of an undetected ``term`` the data allow (profile likelihood).

    The other ``terms`` are refitted for each trial value; the limit is where chi^2 exceeds
    its minimum by ``delta_chi2`` (4: one-sided ~97.7 %, two-sided 95 %).  Used to give Kalibr,
    which refuses zeros, an honest bound instead of nothing.  Returns NaN if not bounded.
    """
    problem = Problem(np.asarray(tau, float), np.asarray(avar, float), np.asarray(edf, float),
                      np.asarray(alpha), rate_hz)
    others = [t for t in terms if t != term and t in IEEE_TERMS]
    if problem.tau.size < 2 or not others:
        return math.nan
    base = shape_columns(problem, others, {})
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
    # Above the best-fitting coefficient the excess only grows (chi^2 is convex in c); below
    # it, where the data may want the term, the excess can pass delta as well, and that
    # crossing is not the limit.
    lo = max(hi - 60.0, math.log(coef[-1])) if coef[-1] > 0 else hi - 60.0
    halvings = max(math.ceil(math.log2((hi - lo) / _LIMIT_RESOLUTION)), 0)
    # First guess: the limit of the linear problem with these weights, c + sqrt(delta) sd(c)
    # (GLS covariance; the re-weighting moves it a little).  The levels given for the ends
    # only make that guess (near the limit the excess grows about as c^2: slope 2 in log c).
    sd = math.sqrt(max(float(np.linalg.pinv(g.T @ g)[-1, -1]), 0.0))
    guess = math.log(max(coef[-1] + math.sqrt(delta_chi2) * sd, math.exp(lo)))
    lo, _ = run(guided(evaluate, lo, hi, halvings, (2.0 * (lo - guess), 2.0 * (hi - guess))))
    return math.sqrt(math.exp(lo))


def coefficient_interval(c, var, level=CI_LEVEL, deterministic=False):
    """
    Two-sided ``level`` interval of sqrt(c) for a squared coefficient c with variance ``var``.

    A noise term's c is a weighted sum of AVAR estimates, each chi-square distributed, so c is
    about c_true chi^2_nu / nu with nu = 2 c^2 / var (Satterthwaite's effective degrees of
    freedom): the interval is c nu / chi^2_nu quantiles, as SP1065 eq. 45 does for one AVAR
    point.  With many degrees of freedom it is c +- z sd; with few (a random walk seen in the
    last decade only) its upper side is the longer one, as the estimates' scatter is.  A
    deterministic term (``deterministic``: the rate ramp), whose error is the noise's drift,
    takes the normal interval c +- z sd.  Returns ``(lo, hi)`` of sqrt(c).
    """
    if not (var > 0 and c > 0):
        return (math.sqrt(max(c, 0.0)),) * 2
    p = 0.5 * (1.0 - level)
    nu = 2.0 * c * c / var
    # chi-square quantiles with upper tail q: 2 Q^-1(nu / 2, q) (scipy's chdtri(nu, q))
    low_q = 2.0 * float(_gammainccinv(0.5 * nu, p))
    high_q = 2.0 * float(_gammainccinv(0.5 * nu, 1.0 - p))
    c, var = float(c), float(var)
    # A term with sd >> c (nu well below 1) has a chi-square so skewed that its upper quantile
    # can lie below nu (the interval would exclude c), its lower one underflow or the upper
    # bound overflow: there the normal interval is the honest statement.
    if deterministic or not (low_q > nu and high_q > 0.0 and c * nu / high_q < 1e300):
        z = two_sided_z(level)
        sd = math.sqrt(var)
        return math.sqrt(max(c - z * sd, 0.0)), math.sqrt(c + z * sd)
    return math.sqrt(c * nu / low_q), math.sqrt(c * nu / high_q)


def two_sided_z(level):
    """
    Return z with P(|Z| < z) = ``level`` for a standard normal Z: Phi^-1((1 + level) / 2).

    z^2 is the chi-square(1) quantile with upper tail 1 - level (no scipy.special import).
    """
    return math.sqrt(2.0 * float(_gammainccinv(0.5, 1.0 - level)))


class FittedModel:
    """Result of :func:`fit_noise_model`: a :class:`NoiseModel` plus intervals per term."""

    def __init__(self, fits, rate_hz, result=None):
        """Wrap per-axis :class:`AxisFit` objects."""
        self.fits = fits
        self.rate_hz = rate_hz
        self.result = result
        self.model = NoiseModel({a: f.terms for a, f in fits.items()}, rate_hz)
        self.intervals = {a: f.intervals for a, f in fits.items()}
        self.chi2 = {a: f.chi2 for a, f in fits.items()}
        self.dof = {a: f.dof for a, f in fits.items()}
        self._upper_limits = {}

    @property
    def axes(self):
        """Fitted axes."""
        return list(self.fits)

    def value(self, axis, term, param='value'):
        """Return a fitted parameter (SI, continuous time), NaN if the term was not detected."""
        return self.model.value(axis, term, param)

    def interval(self, axis, term, param='value', level=CI_LEVEL):
        """
        Return the two-sided ``level`` interval of a parameter, ``(nan, nan)`` if not detected.

        ``level`` defaults to 68.27 % (one standard deviation), the interval stored with the
        fit.  Main parameters: :func:`coefficient_interval` from the squared coefficient and
        its GLS variance (chi-square with Satterthwaite's degrees of freedom; normal for the
        deterministic ramp); tau_c / f0: the stored profile interval's log half-widths scaled
        by z = Phi^-1((1 + level) / 2).
        """
        stored = self.intervals.get(axis, {}).get(term, {}).get(param)
        if stored is None:
            return (math.nan, math.nan)
        if not 0.0 < level < 1.0:
            raise ValueError(f'confidence level {level!r} must be between 0 and 1')
        if abs(level - CI_LEVEL) < 1e-12:
            return stored
        fit = self.fits[axis]
        value = self.model.value(axis, term, param)
        if param == TERMS[term].params[0] and term in fit.coef:
            j = list(fit.coef).index(term)
            return coefficient_interval(fit.coef[term], max(fit.cov[j, j], 0.0), level,
                                        term == 'rate_ramp')
        z = two_sided_z(level)
        lo, hi = stored
        return (value * (lo / value) ** z, value * (hi / value) ** z)

    def alternatives(self, axis):
        """
        Term sets the data of ``axis`` cannot reject, the selected one first.

        Every candidate set whose selection criterion is within :data:`ALTERNATIVE_MARGIN`
        of the best (see there); ``[selected]`` when the terms were named, not selected.
        """
        fit = self.fits.get(axis)
        if fit is None or not fit.terms:
            return []
        selected = list(fit.terms)
        if not fit.candidates:
            return [selected]
        best = fit.candidates[0][0]
        out = [selected]
        rejected = {frozenset(e['terms']) for e in fit.evidence if e['rejected']}
        for crit, names in fit.candidates:
            if (crit - best < ALTERNATIVE_MARGIN and set(names) != set(selected)
                    and frozenset(names) not in rejected):
                out.append(list(names))
        return out

    def rejected(self, axis):
        """
        Term sets the Allan fit left open but another curve contradicts (JSON-ready).

        ``[{'terms': [...], 'by': curve, ...}]``; so far only the Hadamard check of a rate
        random walk against a rate ramp (:mod:`.hadamard_check`, curve ``'ohdev'``, with its
        ``gain``, ``walk_min`` and ``walk_max``), run when :func:`fit_noise_model` is given
        the OHDEV curve.
        """
        fit = self.fits.get(axis)
        return [{'terms': e['terms'], 'by': e['curve'],
                 **{k: v for k, v in e.items() if k not in ('terms', 'curve', 'rejected')}}
                for e in (fit.evidence if fit is not None else []) if e['rejected']]

    def decided_by(self, axis):
        """
        Name the curves that decided the term set of ``axis``; None while alternatives remain.

        ``'oadev'`` when the Allan fit alone leaves no alternative, ``'oadev+ohdev'`` when the
        Hadamard curve rejected the last ones; None when the terms were named or nothing was
        fitted.
        """
        fit = self.fits.get(axis)
        if (fit is None or not fit.terms or not fit.candidates
                or len(self.alternatives(axis)) > 1):
            return None
        curves = ['oadev'] + sorted({e['curve'] for e in fit.evidence if e['rejected']})
        return '+'.join(curves)

    def upper_limit(self, axis, term):
        """
        95 % upper limit of a term the fit of ``axis`` did not select (SI, cached).

        NaN if the term was selected, nothing was, or the data do not bound it (see
        :func:`upper_limit`).  Exporters write it where a consumer needs a number.
        """
        key = (axis, term)
        if key not in self._upper_limits:
            selected = list(self.model.terms.get(axis, {}))
            value = math.nan
            if self.result is not None and selected and term not in selected:
                r, j = self.result, self.result.axis_index(axis)
                value = float(upper_limit(r.tau, r.avar[:, j], r.edf[:, j], r.alpha[:, j],
                                          r.rate_hz, selected + [term], term))
            self._upper_limits[key] = value
        return self._upper_limits[key]

    def model_avar(self, axis, tau):
        """AVAR of the fitted model of an axis at ``tau`` (s)."""
        return _terms.model_avar(self.model.terms.get(axis, {}), tau, self.rate_hz)

    def term_report(self, axis):
        """JSON-ready ``{term: {value, ci, unit, time, conventional}}`` for one axis."""
        out = {}
        for term, params in self.model.terms.get(axis, {}).items():
            main = TERMS[term].params[0]
            lo, hi = self.intervals[axis][term][main]
            conv, conv_unit = conventional(axis, term, params[main])
            entry = {'value': params[main], 'ci': [lo, hi], 'unit': si_unit(axis, term),
                     'time': 'continuous',
                     'conventional': {'value': conv, 'unit': conv_unit,
                                      'ci': [conventional(axis, term, lo)[0],
                                             conventional(axis, term, hi)[0]]}}
            for extra in params:
                if extra != main:
                    entry[extra] = {'value': params[extra],
                                    'ci': list(self.intervals[axis][term][extra]),
                                    'unit': TERMS[term].param_unit(axis, extra)}
            out[term] = entry
        return out


def fit_noise_model(result, terms=None, axes=None, deviations=None):
    """
    Fit noise terms to every axis of an :class:`~imu_allan.core.allan.AllanResult`.

    Parameters
    ----------
    result : AllanResult
        Measured Allan deviation with EDF.
    terms : sequence of str, optional
        Terms to fit on every axis (any of :data:`~imu_allan.core.units.ALL_TERMS`); default:
        automatic selection among the five IEEE terms by BIC.
    axes : sequence of str, optional
        Axes to fit (default all).
    deviations : dict, optional
        ``{kind: DeviationResult}`` of the same record (:func:`imu_allan.deviation`).  With
        ``'ohdev'`` and automatic selection, the Hadamard curve decides between a rate random
        walk and a rate ramp where the Allan fit cannot (:mod:`.hadamard_check`).

    Returns
    -------
    FittedModel

    """
    if isinstance(terms, str):
        terms = [t.strip() for t in terms.split(',') if t.strip()]
    fits = {}
    for axis in (axes or result.axes):
        j = result.axis_index(axis)
        fits[axis] = fit_axis(result.tau, result.avar[:, j], result.edf[:, j],
                              result.alpha[:, j], result.rate_hz, terms,
                              result.n_samples / result.rate_hz)
        ohdev = (deviations or {}).get('ohdev')
        if terms is None and ohdev is not None and axis in ohdev.axes:
            from . import hadamard_check  # (it builds on this module)
            hadamard = hadamard_check.hadamard_problem(ohdev, axis, fits[axis].coef)
            if hadamard is not None:
                allan = Problem(result.tau, result.avar[:, j], result.edf[:, j],
                                result.alpha[:, j], result.rate_hz,
                                result.n_samples / result.rate_hz)
                fits[axis] = hadamard_check.decide(fits[axis], allan, hadamard)
    return FittedModel(fits, result.rate_hz, result)
