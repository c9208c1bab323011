"""
Power-law noise identification per averaging time: lag-1 autocorrelation, B1 ratio below 30.

Which noise dominates at each averaging time decides the EDF and the bias corrections.  The
method is Stable32's (W. J. Riley and C. A. Greenhall, "Power law noise identification using
the lag 1 autocorrelation", Proc. 18th EFTF, 2004; allantools ``autocorr_noise_id``):

1. average the rate samples in non-overlapping blocks of m (K = n // m block means) and remove
   a straight line (a frequency drift would otherwise read as random-walk FM);
2. r1 = lag-1 autocorrelation, delta = r1 / (1 + r1); while delta >= 0.25 and fewer than
   ``dmax`` differences were taken, difference the series once more (d += 1);
3. alpha = -2 (round(delta) + d) with round to the nearest half, i.e. -round(2 delta) - 2 d.

It needs K >= 30 block means.  Where fewer remain (the longest averaging times) the B1 ratio
(Barnes 1969; Howe, Beard, Greenhall and Riley 2000, table 3), the classical variance of the K
block means over their non-overlapping Allan variance, picks the exponent mu of AVAR ~ tau^mu
whose expected B1(K, mu) is nearest (boundaries at the geometric means), as Stable32 does; its
mu = -2 (white or flicker PM, which B1 cannot split) is reported as white PM (alpha = +2).
Why not the package's fit-based :func:`imu_allan.core.allan.estimate.identify_noise`:
docs/method.md section 8.
"""

import numpy as np

#: Fewest block means for the autocorrelation method (Riley & Greenhall 2004).
MIN_ACF_POINTS = 30


def _detrend_linear(z):
    """Remove a least-squares straight line from each row of ``z`` (A, K)."""
    k = z.shape[1]
    t = np.arange(k, dtype=float) - (k - 1) / 2.0
    slope = (z @ t) / float(t @ t)
    return z - z.mean(axis=1, keepdims=True) - slope[:, None] * t


def _lag1(z):
    """Lag-1 autocorrelation of each row (Riley & Greenhall 2004, eq 2)."""
    z = z - z.mean(axis=1, keepdims=True)
    num = np.sum(z[:, :-1] * z[:, 1:], axis=1)
    den = np.sum(z * z, axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(den > 0, num / den, 0.0)


def acf_alpha(z, dmax):
    """Alpha of each row of the block means ``z`` (A, K), K >= 30, by the lag-1 ACF method."""
    z = _detrend_linear(np.asarray(z, dtype=float))
    alpha = np.zeros(z.shape[0], dtype=int)
    done = np.zeros(z.shape[0], dtype=bool)
    for d in range(dmax + 1):
        r1 = _lag1(z)
        delta = r1 / (1.0 + r1)
        stop = ~done & ((delta < 0.25) | (d >= dmax))
        alpha[stop] = (-np.round(2.0 * delta[stop]) - 2 * d).astype(int)
        done |= stop
        if done.all() or z.shape[1] < 3:
            break
        z = np.diff(z, axis=1)
    return alpha


def b1_theory(k, mu):
    """Return the expected B1 ratio for K block means and AVAR ~ tau^mu (Howe et al. 2000)."""
    k = float(k)
    if mu == 2:
        return k * (k + 1.0) / 6.0
    if mu == 1:
        return k / 2.0
    if mu == 0:
        return k * np.log(k) / (2.0 * (k - 1.0) * np.log(2.0))
    if mu == -1:
        return 1.0
    if mu == -2:
        return (k * k - 1.0) / (1.5 * k * (k - 1.0))
    return k * (1.0 - k ** mu) / (2.0 * (k - 1.0) * (1.0 - 2.0 ** mu))


#: mu of AVAR ~ tau^mu -> alpha (mu = -2 is white or flicker PM: reported as white PM).
_MU_ALPHA = {-2: 2, -1: 0, 0: -1, 1: -2, 2: -3}


def b1_alpha(z):
    """Alpha of each row of the block means ``z`` (A, K), K >= 3, by the B1 ratio."""
    k = z.shape[1]
    var = np.var(z, axis=1, ddof=1)
    avar = 0.5 * np.mean(np.diff(z, axis=1) ** 2, axis=1)
    with np.errstate(divide='ignore', invalid='ignore'):
        b1 = np.where(avar > 0, var / avar, 1.0)
    mus = sorted(_MU_ALPHA)
    bounds = [np.sqrt(b1_theory(k, lo) * b1_theory(k, hi)) for lo, hi in zip(mus, mus[1:])]
    idx = np.searchsorted(np.array(bounds), b1)
    return np.array([_MU_ALPHA[mus[i]] for i in idx], dtype=int)


def identify(y, ms, dmax=2, alpha_range=(-2, 2)):
    """
    Dominant alpha for rate samples ``y`` (A, n) at each averaging factor of ``ms``: (T, A).

    ``dmax`` is the most differences the ACF method may take (2 for the Allan family, 3 for
    Hadamard, which also tolerates alpha down to -4); the result is clipped to ``alpha_range``
    (the EDF of a d-th difference variance needs alpha > 1 - 2d).  Averaging times with fewer
    than 3 block means take the alpha of the next shorter averaging time.
    """
    y = np.asarray(y, dtype=float)
    x = np.concatenate([np.zeros((y.shape[0], 1)), np.cumsum(y, axis=1)], axis=1)
    return identify_phase(x, ms, dmax, alpha_range)


#: Most block means the identification looks at (the first ones): with 2^14 the lag-1
#: autocorrelation is known to +-0.008, far finer than the +-0.25 steps that decide alpha, and
#: a long record's shortest averaging times no longer cost passes over all its samples.
MAX_POINTS = 1 << 14


def identify_phase(x, ms, dmax=2, alpha_range=(-2, 2)):
    """:func:`identify` from the phase ``x`` (A, n + 1), x_k = y_0 + ... + y_{k-1}."""
    n = x.shape[1] - 1
    out = np.zeros((len(ms), x.shape[0]), dtype=int)
    last = np.zeros(x.shape[0], dtype=int)
    for i, m in enumerate(ms):
        m = int(m)
        k = min(n // m, MAX_POINTS)
        if k >= 3:
            z = np.diff(x[:, :k * m + 1:m], axis=1) / m  # block means
            last = acf_alpha(z, dmax) if k >= MIN_ACF_POINTS else b1_alpha(z)
        out[i] = last
    return np.clip(out, *alpha_range)
