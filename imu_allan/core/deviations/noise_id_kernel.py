"""
Compiled lag-1 autocorrelation noise identification (numba), imported by :mod:`.api`.

The same steps as :func:`.noise_id.acf_alpha` on the block means of the phase (Riley &
Greenhall 2004: block means of m samples, a least-squares line removed, lag-1
autocorrelation r1, delta = r1 / (1 + r1), difference while delta >= 0.25 and fewer than
``dmax`` differences were taken, alpha = -round(2 delta) - 2 d).  numpy spends most of its
time there on temporaries and on OpenBLAS starting threads for each (A, K) dot product (2-8
ms per averaging time on the shared machine, more than the deviation itself).  Here the
phase points x_{j m} behind the block means (j <= K, at most :data:`.noise_id.MAX_POINTS`
means per m) are first gathered by one pass per axis over the phase, block by block, every
averaging time per block (:func:`_gather`: strided reads of the whole phase per m touched a
new cache line per point), then every averaging time of an axis is identified in one call
from those contiguous points, one job per axis on the package's thread pool.
:func:`.noise_id.identify_phase` is the oracle the tests compare with.
"""

import numpy as np

from .noise_id import b1_alpha, MAX_POINTS, MIN_ACF_POINTS
from ..jit import jit, map_threads

#: Phase points per block of the gathering pass (32 KiB, as :data:`..allan.kernel.BLOCK`).
BLOCK = 4096


@jit(nogil=True)
def gather_block(xa, m, k, b0, b1, out, off):  # pragma: no cover - compiled
    # out[off + j] = xa[j m] for the j <= k whose point j m lies in the block [b0, b1).
    stop = min(b1, k * m + 1)
    j = (b0 + m - 1) // m  # the first point of this block (no division per point)
    q = j * m
    at = off + j
    while q < stop:
        out[at] = xa[q]
        at += 1
        q += m


@jit(nogil=True)
def _gather(xa, ms, ks, offs, out):  # pragma: no cover - compiled; tested vs numpy
    # out[offs[t] + j] = xa[j ms[t]] for j = 0 .. ks[t], block by block over the phase.
    n = xa.shape[0]
    for b0 in range(0, n, BLOCK):
        b1 = min(b0 + BLOCK, n)
        for t in range(ms.shape[0]):
            gather_block(xa, ms[t], ks[t], b0, b1, out, offs[t])


@jit(nogil=True, fastmath=True)
def _acf_alpha(p, m, k, dmax, z):  # pragma: no cover - compiled; tested vs numpy
    # p: the phase points x_0, x_m, .., x_{k m}; z: work array of at least k values.
    # fastmath: the sums vectorised (reassociated); their rounding (1e-16 of r1) moves alpha
    # only where delta lies that close to a step of 0.25, as numpy's own pairwise sums would.
    for j in range(k):
        z[j] = (p[j + 1] - p[j]) / m  # block means
    # Remove the least-squares line: t centred, so the slope is (z . t) / (t . t).
    mean = 0.0
    for j in range(k):
        mean += z[j]
    mean /= k
    centre = (k - 1) / 2.0
    zt = 0.0
    tt = 0.0
    for j in range(k):
        t = j - centre
        zt += z[j] * t
        tt += t * t
    slope = zt / tt
    for j in range(k):
        z[j] = z[j] - mean - slope * (j - centre)
    n = k
    d = 0
    while True:
        mean = 0.0
        for j in range(n):
            mean += z[j]
        mean /= n
        num = 0.0
        den = 0.0
        prev = z[0] - mean
        den += prev * prev
        for j in range(1, n):
            cur = z[j] - mean
            num += prev * cur
            den += cur * cur
            prev = cur
        r1 = num / den if den > 0 else 0.0
        delta = r1 / (1.0 + r1)
        if delta < 0.25 or d >= dmax:  # K >= 30 > dmax + 2: never runs out of points
            return -int(np.rint(2.0 * delta)) - 2 * d
        for j in range(n - 1):
            z[j] = z[j + 1] - z[j]
        n -= 1
        d += 1


@jit(nogil=True)
def _acf_axis(points, ms, ks, offs, dmax, alpha):  # pragma: no cover - compiled
    # alpha[t] for every averaging time with >= 30 means, from one axis's gathered points.
    z = np.empty(max(1, ks.max()))
    for t in range(ms.shape[0]):
        if ks[t] >= MIN_ACF_POINTS:
            alpha[t] = _acf_alpha(points[offs[t]:], ms[t], ks[t], dmax, z)


@jit(nogil=True)
def _axis(xa, ms, ks, offs, dmax, points, alpha):  # pragma: no cover - compiled
    # Gather one axis's points, then identify every averaging time of it.
    _gather(xa, ms, ks, offs, points)
    _acf_axis(points, ms, ks, offs, dmax, alpha)


def layout(n, ms):
    """
    Means per averaging factor and where their points go: ``ks`` (T,), ``offs`` (T + 1,).

    K = min(n // m, :data:`.noise_id.MAX_POINTS`) block means need the phase points
    x_0, x_m, .., x_{K m}, stored at ``offs[t]`` .. ``offs[t] + K``; none (K = 0) where fewer
    than 3 means remain (those averaging times take the previous alpha).
    """
    ms = np.asarray(ms, dtype=np.int64)
    ks = np.array([min(n // int(m), MAX_POINTS) for m in ms], dtype=np.int64)
    ks = np.where(ks >= 3, ks, 0)
    offs = np.concatenate([[0], np.cumsum(ks + 1)]).astype(np.int64)
    return ks, offs


def identify_phase(x, ms, dmax=2, alpha_range=(-2, 2)):
    """:func:`.noise_id.identify_phase`, the ACF steps compiled: alpha (T, A) from x (A, N+1)."""
    x = np.ascontiguousarray(x, dtype=float)
    ms = np.asarray(ms, dtype=np.int64)
    ks, offs = layout(x.shape[1] - 1, ms)
    points = np.empty((x.shape[0], int(offs[-1])))
    acf = np.zeros((x.shape[0], ms.size), dtype=np.int64)
    map_threads(lambda a: _axis(x[a], ms, ks, offs[:-1], dmax, points[a], acf[a]),
                list(range(x.shape[0])))
    return alphas(points, ms, ks, offs, acf, alpha_range)


def alphas(points, ms, ks, offs, acf, alpha_range):
    """
    Alpha (T, A) from the gathered points (A, P) and the ACF results ``acf`` (A, T).

    The B1 ratio where 3 <= K < 30 (:func:`.noise_id.b1_alpha`, numpy: a few averaging
    times), the previous alpha where K < 3, clipped to ``alpha_range``.
    """
    out = np.zeros((len(ms), points.shape[0]), dtype=int)
    last = np.zeros(points.shape[0], dtype=int)
    for t, (m, k) in enumerate(zip(ms, ks)):
        if k >= MIN_ACF_POINTS:
            last = acf[:, t].astype(int)
        elif k >= 3:
            last = b1_alpha(np.diff(points[:, offs[t]:offs[t] + k + 1], axis=1) / int(m))
        out[t] = last
    return np.clip(out, *alpha_range)
