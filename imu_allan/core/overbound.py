"""
Overbounding: a consumer's noise model whose Allan variance lies above the measured one.

Why, and each consumer's model: docs/exports.md ("Raw, overbound or inflated").  Following
Lethander & Taylor ("Conservative estimation of inertial sensor errors using Allan
variance data", NAVIGATION 70(3), 2023), :func:`overbound` chooses the parameters of the
consumer's own model so that its Allan variance is at or above the UPPER bound of the measured
one at every averaging time from tau0 to a horizon, and as small as possible.

The bound at each averaging time is the upper end of the chi-square interval of the measured
Allan deviation with that point's EDF (Greenhall & Riley 2004; NIST SP1065 eq. 45), at 95 %
two-sided (:func:`imu_allan.core.allan.edf.chi2_interval`), squared: an AVAR, unit^2.

The model's AVAR is linear in the squared amplitudes x_j (N^2, K^2, B^2, sigma^2 of a
Gauss-Markov; the shapes of :mod:`imu_allan.core.terms`, with the sampled-data corrections), so
the problem is a linear program over the tau grid::

    minimise   sum_i sum_j x_j s_j(tau_i) / U(tau_i)          (U: the upper bound)
    subject to sum_j x_j s_j(tau_i) >= U(tau_i)  for every tau_i <= horizon,  x_j >= 0.

The objective is the sum over the grid of the model's AVAR relative to the bound (each term
>= 1): it is scale-free (units cancel, a gyro in rad/s and an accelerometer in m/s^2 are
treated alike), and on the log-spaced grid of the estimator it weighs every decade of
averaging time equally, as a filter's horizons are spread; minimising it minimises the mean
over-conservatism over the horizons the filter lives through.  A Gauss-Markov's correlation
time enters non-linearly: it is profiled over a log grid (the LP is solved per tau_c and the
smallest objective kept).  Continuous-time SI throughout; ROS-free.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from .allan.edf import chi2_interval
from .terms import TERMS
from ..errors import InputError

#: Two-sided confidence level of the bound the model must lie above (its upper end).
OVERBOUND_LEVEL = 0.95
#: A constraint counts as tight (the bound is met) within this relative margin.
TIGHT_RTOL = 1e-6
#: Correlation times tried for a Gauss-Markov, per decade, from tau0 / 10 to 100 x horizon.
TAU_C_PER_DECADE = 8
#: The consumer noise model of most estimators: white noise plus a bias random walk.
WHITE_WALK = ('white_noise', 'rate_random_walk')


class OverboundError(InputError):
    """The data give no overbound (no usable bound, no model above it): ``--overbound``."""

    option = '--overbound'

    def __init__(self, problem):
        """Name the option the problem belongs to."""
        super().__init__(self.option, problem)


class HorizonError(OverboundError):
    """The horizon lies outside the measured averaging times: ``--overbound-horizon``."""

    option = '--overbound-horizon'


@dataclass
class OverboundFit:
    """The overbounding parameters of one consumer model for one axis (or a set of axes)."""

    #: ``{term: {param: value}}``, SI, continuous time (the consumer model's terms)
    terms: dict
    #: averaging times of the constraint grid, s (tau0 .. horizon), and the measured upper
    #: bound of the AVAR there, unit^2, and the model's AVAR there (>= ``bound``)
    tau: np.ndarray
    bound: np.ndarray
    model_avar: np.ndarray
    #: averaging times where the model meets the bound, s
    tight_tau: list
    #: longest averaging time constrained, s, and the two-sided level of the bound
    horizon_s: float
    level: float
    #: mean of model / bound over the grid (>= 1; 1 only if the model fits the bound exactly)
    objective: float
    axes: tuple = field(default_factory=tuple)

    def value(self, term, param='value'):
        """Return one parameter (SI), NaN if the model has no such term."""
        return self.terms.get(term, {}).get(param, math.nan)


def upper_bound(result, axes, horizon_s=None, level=OVERBOUND_LEVEL):
    """
    ``(tau, bound)``: the upper end of the measured AVAR's interval up to the horizon.

    ``result`` is an :class:`~imu_allan.core.allan.estimate.AllanResult`; ``axes`` one axis name or
    several (the bound is then their envelope, the largest at each tau: one model for several
    axes, for consumers with one number per sensor).  Points without a finite EDF are left
    out.  :class:`HorizonError` if ``horizon_s`` is outside [tau0, longest tau],
    :class:`OverboundError` if nothing is left.
    """
    axes = [axes] if isinstance(axes, str) else list(axes)
    tau = np.asarray(result.tau, dtype=float)
    if tau.size == 0:
        raise OverboundError('no averaging time was measured')
    horizon = float(tau[-1]) if horizon_s is None else float(horizon_s)
    if not (math.isfinite(horizon) and tau[0] * (1 - 1e-9) <= horizon <= tau[-1] * (1 + 1e-9)):
        raise HorizonError(f'horizon {horizon_s!r} s must lie between the shortest '
                           f'({tau[0]:.4g} s) and the longest ({tau[-1]:.4g} s) averaging time '
                           'measured')
    cols = [result.axis_index(a) for a in axes]
    _, high = chi2_interval(result.adev[:, cols], result.edf[:, cols], level=level)
    bound = np.max(high * high, axis=1) if high.size else np.zeros(tau.size)
    keep = (tau <= horizon * (1 + 1e-9)) & np.all(np.isfinite(high), axis=1) & (bound > 0)
    if not keep.any():
        raise OverboundError(f'no averaging time up to {horizon:.4g} s has a usable bound')
    return tau[keep], bound[keep], horizon


def _solve(columns, bound):
    """LP of the module docstring for fixed shapes; ``(x, objective)`` or None if infeasible."""
    a = columns / bound[:, None]                      # model / bound per unit x_j
    if a.shape[1] == 1:  # one term: the optimum is where its tightest constraint is met
        if not np.all(a[:, 0] > 0):
            return None
        x = 1.0 / float(np.min(a[:, 0]))
        return np.array([x]), float(np.mean(a[:, 0] * x))
    from scipy.optimize import linprog
    scale = 1.0 / np.max(a, axis=0)                   # x_j = scale_j z_j: columns of max 1
    a = a * scale
    c = a.sum(axis=0)
    sol = linprog(c, A_ub=-a, b_ub=-np.ones(bound.size), bounds=[(0, None)] * a.shape[1],
                  method='highs')
    if sol.status != 0:
        return None
    return sol.x * scale, float(sol.fun) / bound.size


def overbound(tau, bound, shapes, rate_hz, horizon_s=None, level=OVERBOUND_LEVEL, axes=()):
    """
    Smallest parameters of a model with terms ``shapes`` whose AVAR is >= ``bound`` at ``tau``.

    ``tau`` (s) and ``bound`` (unit^2): e.g. from :func:`upper_bound`.  ``shapes``: the
    consumer model's terms (names of :data:`~imu_allan.core.terms.TERMS`), e.g. ``WHITE_WALK``
    or ``('white_noise', 'gauss_markov')``, at most one hump term (its position, tau_c, is
    profiled up to 100 x ``horizon_s``, default the last ``tau``).  ``rate_hz``: the data's
    rate (the sampled-data shapes).  ``horizon_s``, ``level`` (the two-sided level the bound
    was computed at) and ``axes`` (those the bound covers) are recorded in the returned
    :class:`OverboundFit`.
    """
    tau = np.asarray(tau, dtype=float)
    bound = np.asarray(bound, dtype=float)
    shapes = tuple(shapes)
    humps = [s for s in shapes if TERMS[s].position is not None]
    if len(humps) > 1:
        raise ValueError(f'at most one term with a position can be profiled, got {humps}')
    if humps and humps[0] != 'gauss_markov':
        raise ValueError(f'{humps[0]} cannot be overbounded (only a Gauss-Markov is profiled)')
    horizon = float(tau[-1]) if horizon_s is None else float(horizon_s)
    positions = [None]
    if humps:
        lo, hi = tau[0] / 10.0, 100.0 * horizon
        count = int(math.ceil(TAU_C_PER_DECADE * math.log10(hi / lo))) + 1
        positions = list(np.geomspace(lo, hi, count))
    best = None
    for position in positions:
        columns = np.column_stack([TERMS[s].shape(tau, rate_hz, position if TERMS[s].position
                                                  else None) for s in shapes])
        solved = _solve(columns, bound)
        if solved is not None and (best is None or solved[1] < best[1]):
            best = (solved[0], solved[1], position, columns)
    if best is None:
        raise OverboundError(f'no {" + ".join(shapes)} model lies above the bound')
    x, objective, position, columns = best
    x = np.maximum(x, 0.0)
    model = columns @ x
    terms = {}
    for s, xj in zip(shapes, x):
        terms[s] = TERMS[s].pack(math.sqrt(xj), position)
    tight = [float(t) for t, m, b in zip(tau, model, bound) if m <= b * (1.0 + TIGHT_RTOL)]
    return OverboundFit(terms, tau, bound, model, tight, horizon, level, objective, tuple(axes))


def overbound_axes(result, axes, shapes, horizon_s=None, level=OVERBOUND_LEVEL):
    """:func:`overbound` of the envelope of ``axes`` of an AllanResult (one axis: a string)."""
    tau, bound, horizon = upper_bound(result, axes, horizon_s, level)
    names = (axes,) if isinstance(axes, str) else tuple(axes)
    return overbound(tau, bound, shapes, result.rate_hz, horizon, level, names)


def white_overbound(result, axes=None, horizon_s=None, level=OVERBOUND_LEVEL):
    """
    Per axis (``axes``, default the result's), the white noise N whose AVAR N^2/tau overbounds.

    The model of a filter without bias states (robot_localization reads one variance per
    message, N^2 f): :func:`overbound` with the single term ``white_noise`` up to the horizon
    (default: the longest measured tau).  Returns an array (len(axes),), SI (continuous
    density), NaN for an axis missing from ``result`` or without a usable bound.
    """
    axes = list(result.axes if axes is None else axes)
    out = np.full(len(axes), math.nan)
    for j, axis in enumerate(axes):
        if axis not in result.axes:
            continue
        try:
            out[j] = overbound_axes(result, axis, ('white_noise',), horizon_s,
                                    level).value('white_noise')
        except OverboundError:  # no finite EDF yet on this axis (absent, or too few samples)
            pass
    return out
