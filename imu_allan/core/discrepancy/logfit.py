"""
Fitting noise terms to one axis in log-deviation, with the gap's own metric.

Weighted least squares of z_i = (ln adev_meas - centre_i) / spread_i over every parameter
(log amplitudes and, for hump terms, log positions), a sandwich covariance under the measured
correlation between averaging times, and the Satterthwaite test of an added term
(:func:`improvement_test`).
"""

import copy
from dataclasses import dataclass, field
import math

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2

from .band import Z95
from ..fit.nnls import nnls_scaled
from ..terms import TERMS
from ..units import ALL_TERMS

_Z68 = 1.0


def position_range(term, tau):
    """Return allowed position of a hump term: its ADEV peak must lie inside the measured span."""
    return TERMS[term].position_range(float(tau[0]), float(tau[-1]))


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
        self.offset = 0.0
        self._shapes = {}

    def with_offset(self, avar):
        """
        Return a copy whose model AVAR gets ``avar`` added (a term held at a fixed size).

        The fit then adjusts the other terms around it; the level they are asked for (the
        start and the amplitude bounds) is the measured one minus the held term's, floored at
        a tenth of the measured where the held term alone overshoots: a lower floor made the
        other terms' bounds (30 x the smallest level asked for) too tight to fit them.
        """
        other = copy.copy(self)  # shares the cache of fixed shapes
        other.offset = self.offset + np.asarray(avar, dtype=float)
        other.target = np.maximum(self.target - avar, 0.1 * self.target)
        return other

    def shape(self, term, position=None):
        """AVAR per unit squared amplitude at this problem's tau (cached for fixed shapes)."""
        if TERMS[term].position:
            return TERMS[term].shape(self.tau, self.rate_hz, position)
        if term not in self._shapes:
            self._shapes[term] = TERMS[term].shape(self.tau, self.rate_hz)
        return self._shapes[term]

    def residual(self, avar):
        """Return z per averaging time of a model AVAR (plus a held term, :meth:`with_offset`)."""
        return (self.y - 0.5 * np.log(np.maximum(avar + self.offset, 1e-300)) - self.bias) \
            / self.sd

    def amplitude_bounds(self, shape):
        ok = shape > 0
        top = math.sqrt(float(np.min(self.target[ok] / shape[ok]))) if ok.any() else 1.0
        return top * 1e-4, top * 30.0


def _nnls_start(prob, names, positions):
    """Relative-error NNLS of squared amplitudes for fixed positions; returns (amps, Q)."""
    shapes = np.column_stack([prob.shape(t, positions.get(t)) for t in names])
    w = 1.0 / (2.0 * prob.target * prob.sd)
    coef = nnls_scaled(shapes * w[:, None], prob.target * w)
    avar = shapes @ coef
    if not np.all(avar > 0):
        return np.sqrt(coef), math.inf
    z = prob.residual(avar)
    return np.sqrt(coef), float(z @ z)


@dataclass(frozen=True)
class _Layout:
    """
    The parameter vector of one fit: ln amplitude per term, then ln position per free hump.

    ``names`` the terms in package order, ``free`` the hump terms whose position is fitted,
    ``fixed`` the held positions ({term: position}: tau_c, s; frequency_hz, Hz), ``ranges``
    ({term: (lo, hi)}) a free position's range where it replaces the default one.
    """

    names: list
    free: list
    fixed: dict
    ranges: dict
    tau: np.ndarray

    def span(self, term):
        """Return the allowed positions (lo, hi) of a free hump term."""
        return self.ranges[term] if term in self.ranges else position_range(term, self.tau)

    def split(self, theta):
        """Return the amplitudes and the ``{term: position}`` (held ones too) of ``theta``."""
        amps = np.exp(theta[:len(self.names)])
        return amps, {**self.fixed, **dict(zip(self.free, np.exp(theta[len(self.names):])))}

    def labels(self):
        """Return ``(term, 'amp' or 'pos')`` per entry of the parameter vector."""
        return [(t, 'amp') for t in self.names] + [(t, 'pos') for t in self.free]


def _starts(prob, layout, init, hints):
    """
    Return the starting points ``(Q, positions, amplitudes)`` of the search.

    The two best (least Q) of a grid of positions, 14 log-spaced over each free hump's span
    plus the hints and ``init``'s own position, with amplitudes by NNLS; then ``init`` itself
    when it has every term (Q unknown: inf).
    """
    names, nl, fixed = layout.names, layout.free, layout.fixed
    grids = []
    for t in nl:
        lo, hi = layout.span(t)
        grid = list(np.geomspace(lo, hi, 14))
        for extra in (hints.get(t), TERMS[t].unpack(init[t])[1] if t in init else None):
            if extra is not None and lo <= extra <= hi:
                grid.append(extra)
        grids.append(grid)
    starts = []
    for combo in (np.array(np.meshgrid(*grids)).reshape(len(nl), -1).T if nl else [()]):
        positions = {**fixed, **dict(zip(nl, combo))}
        amps, q = _nnls_start(prob, names, positions)
        starts.append((q, positions, amps))
    starts.sort(key=lambda s: s[0])
    starts = starts[:2]
    if init and all(t in init for t in names):
        positions = {**fixed, **{t: TERMS[t].unpack(init[t])[1] for t in nl}}
        amps = np.array([TERMS[t].unpack(init[t])[0] for t in names])
        starts.append((math.inf, positions, amps))
    return starts


def _bounds(prob, layout):
    """Return the lower and upper bounds of the parameter vector (ln units)."""
    bounds_lo, bounds_hi = [], []
    for t in layout.names:
        if t in layout.fixed:
            shape = prob.shape(t, layout.fixed[t])
        else:
            shape = prob.shape(t, math.sqrt(np.prod(layout.span(t)))
                               if t in layout.free else None)
        if TERMS[t].position:  # amplitude bound from the hump's peak level, position-independent
            peak = float(np.max(shape))
            top = math.sqrt(float(np.max(prob.target)) / peak)
            lo, hi = top * 1e-5, top * 30.0
        else:
            lo, hi = prob.amplitude_bounds(shape)
        bounds_lo.append(math.log(lo))
        bounds_hi.append(math.log(hi))
    for t in layout.free:
        lo, hi = layout.span(t)
        bounds_lo.append(math.log(lo))
        bounds_hi.append(math.log(hi))
    return np.array(bounds_lo), np.array(bounds_hi)


def _best_solution(prob, layout, starts, bounds):
    """Return ``(Q, solution)`` of the bounded least squares from the start with least Q."""
    bounds_lo, bounds_hi = bounds

    def fun(theta):
        amps, pos = layout.split(theta)
        avar = np.zeros(prob.tau.shape)
        for t, a in zip(layout.names, amps):
            avar = avar + a * a * prob.shape(t, pos.get(t))
        return prob.residual(avar)

    best = None
    for _, positions, amps in starts:
        x0 = np.concatenate([np.log(np.maximum(amps, 1e-300)),
                             np.log([positions[t] for t in layout.free])]) if layout.free else \
            np.log(np.maximum(amps, 1e-300))
        span = bounds_hi - bounds_lo
        x0 = np.clip(x0, bounds_lo + 1e-3 * span, bounds_hi - 1e-3 * span)
        sol = least_squares(fun, x0, bounds=(bounds_lo, bounds_hi), method='trf',
                            x_scale=1.0, max_nfev=300)
        q = float(sol.fun @ sol.fun)
        if best is None or q < best[0]:
            best = (q, sol)
    return best


def _axis_fit(prob, layout, q, sol, bounds):
    """Return the :class:`AxisFit` of a solution: parameters, covariance, intervals, bounds."""
    bounds_lo, bounds_hi = bounds
    theta = sol.x
    jac = sol.jac
    params = {}
    amps, pos = layout.split(theta)
    for t, a in zip(layout.names, amps):
        params[t] = TERMS[t].pack(float(a), float(pos[t]) if t in pos else None)
    cov = _sandwich(jac, prob.corr)
    labels = layout.labels()
    fit = AxisFit(params, q, sol.fun, jac, labels, cov)
    span = bounds_hi - bounds_lo
    for i, (t, kind) in enumerate(labels):
        pname = TERMS[t].params[0 if kind == 'amp' else 1]
        sd = math.sqrt(max(cov[i, i], 0.0)) if np.isfinite(cov[i, i]) else math.inf
        fit.intervals68.setdefault(t, {})[pname] = _log_interval(theta[i], _Z68 * sd)
        fit.intervals95.setdefault(t, {})[pname] = _log_interval(theta[i], Z95 * sd)
        fit.at_bound.setdefault(t, {})[pname] = bool(
            theta[i] - bounds_lo[i] < 1e-2 * span[i] or bounds_hi[i] - theta[i] < 1e-2 * span[i])
    return fit


def fit_terms(prob, names, init=None, hints=None, fixed_positions=None, ranges=None):
    """
    Fit ``names`` (all amplitudes and positions free) to a :class:`FitProblem`.

    ``init`` ({term: params}) and ``hints`` ({term: position}) seed the search; hump terms are
    started from a grid of positions over the measured span plus the hints.
    ``fixed_positions`` ({term: position}) holds those hump terms' positions (tau_c, s;
    frequency_hz, Hz) at the given values, so only their amplitudes are fitted; ``ranges``
    ({term: (lo, hi)}) replaces a free position's default range (peak inside the span).
    """
    names = [t for t in ALL_TERMS if t in names]
    fixed = dict(fixed_positions or {})
    free = [t for t in names if TERMS[t].position and t not in fixed]
    layout = _Layout(names, free, fixed, ranges or {}, prob.tau)
    starts = _starts(prob, layout, init or {}, hints or {})
    bounds = _bounds(prob, layout)
    q, sol = _best_solution(prob, layout, starts, bounds)
    return _axis_fit(prob, layout, q, sol, bounds)


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


def satterthwaite(jac_nuisance, jac_added, corr):
    """
    Satterthwaite match c chi-square(h) of the drop in sum z^2 when ``jac_added`` is added.

    Under the null z ~ N(0, R), the drop is z' P z with P the projection on the added
    directions orthogonal to the nuisance ones (``jac_nuisance``: None or no columns for
    none); c = tr(PRPR) / tr(PR), h = tr(PR)^2 / tr(PRPR).  Returns ``(c, h)``, or None when
    the added directions vanish or a trace is not positive.
    """
    x = jac_added
    if jac_nuisance is not None and jac_nuisance.size:
        x = x - jac_nuisance @ (np.linalg.pinv(jac_nuisance) @ x)
    if not np.any(np.abs(x) > 0):
        return None
    proj = x @ np.linalg.pinv(x)
    pr = proj @ corr
    e = float(np.trace(pr))
    v = float(np.sum(pr * pr.T))
    if e <= 0 or v <= 0:
        return None
    return v / e, e * e / v


def improvement_test(delta_q, jac_nuisance, jac_added, corr):
    """
    p-value of a drop ``delta_q`` in sum z^2 when columns ``jac_added`` are added.

    Under the null (the smaller model is complete) the drop is matched by c chi-square(h)
    (:func:`satterthwaite`).  Returns ``(p, h)``.
    """
    if delta_q <= 0:
        return 1.0, 0.0
    match = satterthwaite(jac_nuisance, jac_added, corr)
    if match is None:
        return 1.0, 0.0
    c, h = match
    return float(chi2.sf(delta_q / c, h)), h
