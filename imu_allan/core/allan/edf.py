"""
Equivalent degrees of freedom (Greenhall & Riley 2004) and chi-square confidence intervals.

C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
differences", Proc. 35th PTTI Meeting (2003/2004): the "combined EDF" algorithm of NIST
SP1065, Stable32 and allantools ``ci.edf_greenhall``, for the Allan and Hadamard families,
modified or not, overlapping or not.  A variance is described by

- ``d``: order of the phase difference (2 Allan, 3 Hadamard),
- ``F``: filter factor (``m`` unmodified, 1 modified: the phase is averaged over m samples),
- ``S``: stride factor (1 non-overlapping, ``m`` fully overlapping: stride tau / S),

and the noise by the frequency-PSD exponent alpha: +2 white PM (quantization), +1 flicker PM,
0 white FM (white noise), -1 flicker FM (bias instability), -2 random-walk FM (rate random
walk, ramp), -3, -4 (alpha + 2d must exceed 1).  Eqs (7)-(10) of the paper define the basic
sum over J lags; where J would exceed ``J_max = 100`` the paper switches to the large-J
asymptotes of its Tables 1-3.  :func:`edf_greenhall`'s ``tables=True`` is the paper exactly
(Stable32's printed bounds, :mod:`imu_allan.core.deviations`; allantools' ``edf_greenhall``
to 1e-9); ``tables=False`` evaluates the basic sum itself wherever the paper uses a table:
exactly up to 4096 lags, beyond that (infinite-filter limit only) as Euler-Maclaurin's
integral, 32-point Gauss-Legendre between the kinks at j = S, 2S, ..., plus half end-values
(within 7e-7 of the exact sum at the smallest such m, 1366, and 6e-8 from m = 5000 on).
:func:`edf_oadev` is that for the overlapping Allan variance, its M-free parts cached
(:func:`_lag_moments`; docs/method.md sections 2 and 7).
"""

import functools
import math

import numpy as np

from ..scipy_compiled import function

#: Inverse of the regularized upper incomplete gamma function Q(a, x) (scipy's compiled ufunc,
#: loaded without ``scipy.special``'s import cost; see :mod:`..scipy_compiled`).
_gammainccinv = function('special', '_special_ufuncs', 'gammainccinv')

#: The 1-sigma (68.27 %) two-sided confidence level used throughout the package.
CI_LEVEL = math.erf(1.0 / math.sqrt(2.0))
_J_MAX = 100  # the paper's switch to its tables (and to the infinite-filter limit)
_SUM_POINTS = 4096  # longer lag sums are integrated (Euler-Maclaurin, Gauss-Legendre)
_GL32 = np.polynomial.legendre.leggauss(32)  # nodes on [-1, 1] and weights
_SUM_BLOCK = 1 << 16  # lags summed at a time where they are summed exactly

#: Table 1 (modified variances, F = 1): alpha -> {d: (a0, a1)}.
_TABLE1 = {
    2: {1: (2.0 / 3.0, 1.0 / 3.0), 2: (7.0 / 9.0, 0.5), 3: (22.0 / 25.0, 2.0 / 3.0)},
    1: {1: (0.840, 0.345), 2: (0.997, 0.616), 3: (1.141, 0.843)},
    0: {1: (1.079, 0.368), 2: (1.033, 0.607), 3: (1.184, 0.848)},
    -1: {2: (1.048, 0.534), 3: (1.180, 0.816)},
    -2: {2: (1.302, 0.535), 3: (1.175, 0.777)},
    -3: {3: (1.194, 0.703)},
    -4: {3: (1.489, 0.702)},
}
#: Table 2 (unmodified variances, F = m): alpha -> {d: (a0, a1)}.
_TABLE2 = {
    2: {1: (1.5, 0.5), 2: (35.0 / 18.0, 1.0), 3: (231.0 / 100.0, 1.5)},
    1: {1: (78.6, 25.2), 2: (790.0, 410.0), 3: (9950.0, 6520.0)},
    0: {1: (2.0 / 3.0, 1.0 / 6.0), 2: (2.0 / 3.0, 1.0 / 3.0), 3: (7.0 / 9.0, 0.5)},
    -1: {2: (0.852, 0.375), 3: (0.997, 0.617)},
    -2: {2: (1.079, 0.368), 3: (1.033, 0.607)},
    -3: {3: (1.053, 0.553)},
    -4: {3: (1.302, 0.535)},
}
#: Table 3 (flicker PM, unmodified): d -> (b0, b1) of the log denominator b0 + b1 ln m.
_TABLE3 = {1: (6.0, 4.0), 2: (15.23, 12.0), 3: (47.8, 40.0)}

#: Eq (9): the d-th difference of sx with unit step, sz = sum_k w_k sx(t + k): (shifts, w).
_DIFF = {1: ((0.0, -1.0, 1.0), (2.0, -1.0, -1.0)),
         2: ((0.0, -1.0, 1.0, -2.0, 2.0), (6.0, -4.0, -4.0, 1.0, 1.0)),
         3: ((0.0, -1.0, 1.0, -2.0, 2.0, -3.0, 3.0), (20.0, -15.0, -15.0, 6.0, 6.0, -1.0, -1.0))}


def _sw(t, alpha):
    """Eq (7): generalized autocovariance of the integrated phase, up to sign and scale."""
    t = np.abs(np.asarray(t, dtype=float))
    with np.errstate(divide='ignore', invalid='ignore'):
        if alpha % 2 == 0:  # even exponents: |t|^(3 - alpha) (the sign cancels in the EDF)
            return t ** (3 - alpha)
        # odd exponents: t^(3 - alpha) ln|t|, 0 at t = 0
        return np.where(t > 0, t ** (3 - alpha) * np.log(np.where(t > 0, t, 1.0)), 0.0)


def _sx(t, f, alpha):
    """Eq (8): the phase filtered by the F-point average (F = inf: the continuous limit)."""
    if math.isinf(f):
        return _sw(t, alpha + 2)
    return f * f * (2.0 * _sw(t, alpha) - _sw(t - 1.0 / f, alpha) - _sw(t + 1.0 / f, alpha))


def _sz(t, f, alpha, d):
    """Eq (9): the d-th difference of sx; the shifted copies of t in one call of sx."""
    shifts, weights = _DIFF[d]
    sx = _sx(np.add.outer(shifts, t), f, alpha)  # (each call has a fixed cost: it dominated)
    out = weights[0] * sx[0]
    for w, row in zip(weights[1:], sx[1:]):
        out = out + w * row
    return out


@functools.lru_cache(maxsize=65536)
def edf_greenhall(alpha, d, m, n_phase, overlapping, modified, tables=True):
    """
    EDF of a d-th difference variance at averaging factor ``m`` (Greenhall & Riley 2004, 3.4).

    ``alpha``, ``d``: as in the module docstring (alpha + 2 d > 1); ``m`` = tau / tau0 >= 1;
    ``n_phase``: phase points (rate samples + 1); ``overlapping``: stride S = m (else 1);
    ``modified``: filter F = 1 (else m); ``tables``: above J = 100 lags the paper's tables
    (True) or the basic sum (False).  Returns nan where the record holds no complete difference.
    """
    alpha, d, m = int(alpha), int(d), int(m)
    if alpha + 2 * d <= 1:
        raise ValueError(f'alpha={alpha} is not allowed with d={d} (alpha + 2d must exceed 1)')
    f = 1 if modified else m
    s = m if overlapping else 1
    big_l = m // f + m * d  # length of the filter applied to the phase samples
    if n_phase < big_l:
        return math.nan
    big_m = 1 + math.floor(s * (n_phase - big_l) / m)  # number of summands of the estimator
    j_count = min(big_m, (d + 1) * s)
    r = big_m / s
    if not modified and alpha == 2:  # case 4: unmodified white PM, closed form
        k = math.ceil(r)
        if k <= d:  # the paper's short-record sum (r <= d)
            sum_sq = sum(math.comb(2 * d, d - j) ** 2 * (1.0 - j / r) for j in range(1, k))
            return 1.0 / ((1.0 + 2.0 * sum_sq / math.comb(2 * d, d) ** 2) / big_m)
        a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
        return 1.0 / ((a0 - d / 2.0 / r) / big_m)
    if not modified and alpha <= 0 and m * (d + 1) > _J_MAX:
        f = math.inf  # cases 1-3: the infinite-filter limit for long filters
    if not tables or j_count <= _J_MAX:  # cases 1-3 alike: the basic sum
        return _exact(alpha, d, s, f, j_count, big_m)
    if alpha == 1 and not modified:  # case 3: unmodified flicker PM
        b0, b1 = _TABLE3[d]
        if r > d + 1:
            a0, a1 = _TABLE2[1][d]
            return 1.0 / ((a0 - a1 / r) / ((b0 + b1 * math.log(m)) ** 2 * r))
        m_prime = _J_MAX / r
        return _summed(_J_MAX, _J_MAX, m_prime, m_prime, 1, d, (b0 + b1 * math.log(m)) ** 2)
    if r > d + 1:  # cases 1 and 2: Table 1 (modified) or 2
        a0, a1 = (_TABLE1 if modified else _TABLE2)[alpha][d]
        return 1.0 / ((a0 - a1 / r) / r)
    return _summed(_J_MAX, _J_MAX, _J_MAX / r, f, alpha, d)


def edf_oadev(alpha, m, n_phase):
    """
    EDF of the overlapping Allan variance, the exact sums (no tables).

    :func:`edf_greenhall` with d = 2, F = S = m: ``alpha`` the noise, ``m`` = tau / tau0,
    ``n_phase`` phase points (rate samples + 1).
    """
    return edf_greenhall(alpha, 2, m, n_phase, True, False, False)


def _exact(alpha, d, s, f, j_count, big_m):
    """EDF from the basic sum over ``j_count`` lags, by :func:`_lag_moments` when J = (d+1)S."""
    if j_count == (d + 1) * s:  # every weight is linear in 1/M: the cached M-free parts
        sz0_sq, a, b = _lag_moments(alpha, d, s, f)
        return sz0_sq * big_m / (a - b / big_m)
    return _summed(j_count, big_m, s, f, alpha, d)


def _summed(j_count, big_m, s, f, alpha, d, norm=None):
    """
    EDF ``norm M`` over eq (10), the basic sum over J lags (``norm`` None: sz(0)^2).

    sum = sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{j<J} (1 - j/M) sz(j/S)^2.
    """
    sz0 = float(_sz(0.0, f, alpha, d))
    basic = (sz0 * sz0 + (1.0 - j_count / big_m) * float(_sz(j_count / s, f, alpha, d)) ** 2
             + 2.0 * _lag_sums(j_count, s, f, alpha, d, (lambda j: 1.0 - j / big_m,))[0])
    return (sz0 * sz0 if norm is None else norm) * big_m / basic


@functools.lru_cache(maxsize=65536)
def _lag_moments(alpha, d, s, f):
    """
    Greenhall's basic sum for J = (d + 1) S as ``a - b / M``: ``(sz(0)^2, a, b)``.

    With J = (d + 1) S every term of the sum is linear in 1/M (the weights are 1 - j/M), so
    the sum splits into two M-free parts: the EDF of any record length then costs a division.
    The long-lag integration of :func:`_lag_sums` is linear in the summand as well.
    """
    sz0 = float(_sz(0.0, f, alpha, d))
    j_count = (d + 1) * s
    end = float(_sz(float(d + 1), f, alpha, d)) ** 2
    s0, s1 = _lag_sums(j_count, s, f, alpha, d, (None, lambda j: j))
    return sz0 * sz0, sz0 * sz0 + end + 2.0 * s0, j_count * end + 2.0 * s1


def _lag_sums(j_count, s, f, alpha, d, weights):
    """
    sum_{j=1}^{J-1} w(j) sz(j/S)^2 for each weight function w (None: 1), exactly or integrated.

    In the infinite-filter limit (f = inf) the summand is smooth in j apart from kinks at
    j = S, 2S, ..., so above 4096 lags the sum is the integral (Gauss-Legendre on each piece
    between the kinks) plus the half end-values (Euler-Maclaurin; accuracy in the module
    docstring); a finite filter has kinks at every lag, so it is always summed.  The weights
    share one evaluation of sz (the EDF needs the sums with 1 and with j; sz costs the most).
    """
    def weighted(j, sz_sq):
        return [sz_sq if w is None else w(j) * sz_sq for w in weights]
    if j_count <= _SUM_POINTS or not math.isinf(f):
        # In blocks of lags: a long record's 3m lags at once would take ~100 MB.
        totals = [0.0] * len(weights)
        for lo in range(1, j_count, _SUM_BLOCK):
            j = np.arange(lo, min(lo + _SUM_BLOCK, j_count), dtype=float)
            for i, g in enumerate(weighted(j, _sz(j / s, f, alpha, d) ** 2)):
                totals[i] += float(np.sum(g))
        return totals
    kinks = [k * float(s) for k in range(1, d + 1)]
    edges = np.unique(np.clip([1.0, *kinks, j_count - 1.0], 1.0, j_count - 1.0))
    half = 0.5 * np.diff(edges)[:, None]
    nodes = (half * _GL32[0] + (edges[:-1, None] + half)).ravel()
    gl_weights = (half * _GL32[1]).ravel()
    j = np.concatenate([nodes, [1.0, j_count - 1.0]])  # the nodes, then the two ends
    return [float(np.sum(gl_weights * g[:-2]) + 0.5 * (g[-2] + g[-1]))
            for g in weighted(j, _sz(j / s, f, alpha, d) ** 2)]


def chi2_interval(adev, edf, level=CI_LEVEL):
    """
    Chi-square interval of a deviation with ``edf`` degrees of freedom (SP1065 eq. 45).

    Returns ``(low, high)`` with the same shape as ``adev``.
    """
    adev = np.asarray(adev, dtype=float)
    edf = np.asarray(edf, dtype=float)
    p = (1.0 - level) / 2.0
    with np.errstate(divide='ignore', invalid='ignore'):
        # The chi-square quantile with upper tail q is 2 Q^-1(k / 2, q) (scipy's chdtri(k, q),
        # chi2.ppf(1 - q, k), computes exactly this).
        low = adev * np.sqrt(edf / (2.0 * _gammainccinv(0.5 * edf, p)))
        high = adev * np.sqrt(edf / (2.0 * _gammainccinv(0.5 * edf, 1.0 - p)))
    return low, high
