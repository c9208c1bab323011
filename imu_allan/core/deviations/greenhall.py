"""
Greenhall & Riley (2004) equivalent degrees of freedom for every finite-difference variance.

C. A. Greenhall and W. J. Riley, "Uncertainty of stability variances based on finite
differences", Proc. 35th PTTI Meeting (2003/2004): the "combined EDF" algorithm that Stable32
(and allantools ``ci.edf_greenhall``) use for the Allan and Hadamard families, modified or not,
overlapping or not.  A variance is described by

- ``d``: order of the phase difference (2 Allan, 3 Hadamard),
- ``F``: filter factor (``m`` unmodified, 1 modified: the phase is averaged over m samples),
- ``S``: stride factor (1 non-overlapping, ``m`` fully overlapping: stride tau / S),

and the noise by the frequency-PSD exponent alpha (+2 white PM .. -4 random-run FM; alpha + 2d
must exceed 1).  Eqs (7)-(10) of the paper define the basic sum; Tables 1-3 give its
large-J asymptotes, used where the sum would have more than ``J_max = 100`` terms, exactly as
the paper (and Stable32) do.  The unmodified, fully overlapping Allan case (d = 2, F = S = m) is
:func:`imu_allan.core.allan.edf.edf_oadev`, which sums exactly where the paper uses Table 2 (within
0.3 % of it); :func:`edf_greenhall` follows the paper in every case, which is what the printed
Stable32 bounds are made of.
"""

import functools
import math

import numpy as np

_J_MAX = 100

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

#: Binomial weights of the d-th difference, eq (9): sz = sum_k w_k sx(t + k).
_DIFF = {1: ((0, 2.0), (-1, -1.0), (1, -1.0)),
         2: ((0, 6.0), (-1, -4.0), (1, -4.0), (-2, 1.0), (2, 1.0)),
         3: ((0, 20.0), (-1, -15.0), (1, -15.0), (-2, 6.0), (2, 6.0), (-3, -1.0), (3, -1.0))}


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
    """Eq (9): the d-th difference of sx with unit step."""
    t = np.asarray(t, dtype=float)
    return sum(w * _sx(t + k, f, alpha) for k, w in _DIFF[d])


def _basic_sum(j_count, big_m, s, f, alpha, d):
    """Eq (10): sz(0)^2 + (1 - J/M) sz(J/S)^2 + 2 sum_{j<J} (1 - j/M) sz(j/S)^2."""
    j = np.arange(1, int(j_count), dtype=float)
    inner = np.sum((1.0 - j / big_m) * _sz(j / s, f, alpha, d) ** 2)
    return (float(_sz(0.0, f, alpha, d)) ** 2
            + (1.0 - j_count / big_m) * float(_sz(j_count / s, f, alpha, d)) ** 2
            + 2.0 * float(inner))


@functools.lru_cache(maxsize=65536)
def edf_greenhall(alpha, d, m, n_phase, overlapping, modified):
    """
    EDF of a d-th difference variance at averaging factor ``m`` (Greenhall & Riley 2004, 3.4).

    Parameters
    ----------
    alpha : int
        Frequency-PSD exponent of the dominant noise (+2 .. -4), alpha + 2 d > 1.
    d : int
        1 first difference, 2 Allan, 3 Hadamard.
    m : int
        Averaging factor.
    n_phase : int
        Number of phase points (rate samples + 1).
    overlapping, modified : bool
        Stride S = m (else 1); filter F = 1 (else m).

    Returns nan where the record holds no complete difference.

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
    if modified:  # case 1: modified variances, every alpha
        if j_count <= _J_MAX:
            inv = _basic_sum(j_count, big_m, s, 1, alpha, d) / (
                float(_sz(0.0, 1, alpha, d)) ** 2 * big_m)
        elif r > d + 1:
            a0, a1 = _TABLE1[alpha][d]
            inv = (a0 - a1 / r) / r
        else:
            inv = _basic_sum(_J_MAX, _J_MAX, _J_MAX / r, 1, alpha, d) / (
                float(_sz(0.0, 1, alpha, d)) ** 2 * _J_MAX)
        return 1.0 / inv
    if alpha <= 0:  # case 2: unmodified, alpha <= 0
        if j_count <= _J_MAX:
            f_eff = m if m * (d + 1) <= _J_MAX else math.inf
            inv = _basic_sum(j_count, big_m, s, f_eff, alpha, d) / (
                float(_sz(0.0, f_eff, alpha, d)) ** 2 * big_m)
        elif r > d + 1:
            a0, a1 = _TABLE2[alpha][d]
            inv = (a0 - a1 / r) / r
        else:
            inv = _basic_sum(_J_MAX, _J_MAX, _J_MAX / r, math.inf, alpha, d) / (
                float(_sz(0.0, math.inf, alpha, d)) ** 2 * _J_MAX)
        return 1.0 / inv
    if alpha == 1:  # case 3: unmodified flicker PM
        if j_count <= _J_MAX:
            inv = _basic_sum(j_count, big_m, s, m, 1, d) / (
                float(_sz(0.0, m, 1, d)) ** 2 * big_m)
        else:
            b0, b1 = _TABLE3[d]
            if r > d + 1:
                a0, a1 = _TABLE2[1][d]
                inv = (a0 - a1 / r) / ((b0 + b1 * math.log(m)) ** 2 * r)
            else:
                m_prime = _J_MAX / r
                inv = _basic_sum(_J_MAX, _J_MAX, m_prime, m_prime, 1, d) / (
                    (b0 + b1 * math.log(m)) ** 2 * _J_MAX)
        return 1.0 / inv
    # case 4: unmodified white PM, closed form
    k = math.ceil(r)
    if k <= d:  # the paper's short-record sum (r <= d)
        sum_sq = sum(math.comb(2 * d, d - j) ** 2 * (1.0 - j / r) for j in range(1, k))
        inv = (1.0 + 2.0 * sum_sq / math.comb(2 * d, d) ** 2) / big_m
        return 1.0 / inv
    a0 = math.comb(4 * d, 2 * d) / math.comb(2 * d, d) ** 2
    a1 = d / 2.0
    return 1.0 / ((a0 - a1 / r) / big_m)
