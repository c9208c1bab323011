"""
Compiled overlapping Allan variance (numba), imported by :mod:`.estimate` on use.

Compiled once per install (:mod:`..jit`).  Where the compiled code could not go into this
package's own ``__pycache__``, a one-line warning says where it went; where no directory is
writable at all, the warning says the kernel is compiled in every process and how to avoid it.

Speed (``bench/bench_allan.py``, ``docs/benchmarks.md``): the second differences
x_{k+2m} - 2 x_{k+m} + x_k of all averaging times are summed block by block, :data:`BLOCK`
phase points at a time (32 KiB, the L1 data cache), every averaging time per block and four at
a time sharing the x_k stream.  One pass over an axis thus reads each phase point from memory
once and the 2 m_max window behind the block from the L2/L3 caches, where one pass per averaging
time streamed the whole phase from memory about 100 times.  Sums of at most BLOCK terms are
added to the totals, which keeps the float64 rounding of the long sums small.  The work is cut
into (axis, range of k) jobs run on threads (the kernels release the GIL), which balances
better than a static split when other processes share the cores.
"""

import logging
import os

import numpy as np

from ..jit import jit, map_threads, UNCACHED

#: Phase points per block (32 KiB of float64: the L1 data cache of current x86 cores).
BLOCK = 4096

_LOG = logging.getLogger(__name__)


@jit(fastmath=True, nogil=True, inline='never')
def _sum_one(xa, m, k0, k1):  # pragma: no cover - compiled; tested against avar_reference
    # Three views indexed from 0 in a function of its own: the form LLVM vectorises.
    x2, x1, x0 = xa[k0 + 2 * m:], xa[k0 + m:], xa[k0:]
    s = 0.0
    for k in range(k1 - k0):
        d = x2[k] - 2.0 * x1[k] + x0[k]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _sum_four(xa, ma, mb, mc, md, k0, k1):  # pragma: no cover - compiled
    # Four averaging times in one loop: x_k is loaded once for the four (9 loads per 4 terms
    # instead of 12) and four accumulators hide the add latency.
    x0 = xa[k0:]
    a1, a2 = xa[k0 + ma:], xa[k0 + 2 * ma:]
    b1, b2 = xa[k0 + mb:], xa[k0 + 2 * mb:]
    c1, c2 = xa[k0 + mc:], xa[k0 + 2 * mc:]
    d1, d2 = xa[k0 + md:], xa[k0 + 2 * md:]
    sa = sb = sc = sd = 0.0
    for k in range(k1 - k0):
        v = x0[k]
        da = a2[k] - 2.0 * a1[k] + v
        db = b2[k] - 2.0 * b1[k] + v
        dc = c2[k] - 2.0 * c1[k] + v
        dd = d2[k] - 2.0 * d1[k] + v
        sa += da * da
        sb += db * db
        sc += dc * dc
        sd += dd * dd
    return sa, sb, sc, sd


@jit(nogil=True)
def _axis_range(xa, ms, k_lo, k_hi, acc):  # pragma: no cover - compiled
    # acc[t] += sum of squared second differences at ms[t] (ascending) for k in [k_lo, k_hi).
    n_phase = xa.shape[0]
    n_tau = ms.shape[0]
    for k0 in range(k_lo, k_hi, BLOCK):
        k1 = min(k0 + BLOCK, k_hi)
        for i0 in range(0, n_tau, 4):
            if i0 + 3 < n_tau:
                # The group's common range: k < n_phase - 2 m of its largest m.
                k1g = min(k1, n_phase - 2 * ms[i0 + 3])
                if k1g > k0:
                    sa, sb, sc, sd = _sum_four(xa, ms[i0], ms[i0 + 1], ms[i0 + 2], ms[i0 + 3],
                                               k0, k1g)
                    acc[i0] += sa
                    acc[i0 + 1] += sb
                    acc[i0 + 2] += sc
                    acc[i0 + 3] += sd
                lo, top = max(k0, k1g), i0 + 3
            else:
                lo, top = k0, n_tau
            for t in range(i0, top):  # the shorter averaging times run further
                k1t = min(k1, n_phase - 2 * ms[t])
                if k1t > lo:
                    acc[t] += _sum_one(xa, ms[t], lo, k1t)


@jit(nogil=True)
def _column_sums(y, a_lo, a_hi, k_lo, k_hi):  # pragma: no cover - compiled
    # Sums of BLOCK rows added to the totals: the rounding error of a long sum of values with a
    # large mean (accelerometers: 9.8) stays ~1e-16 relative instead of growing with n.
    total = np.zeros(a_hi - a_lo)
    part = np.zeros(a_hi - a_lo)
    for k in range(k_lo, k_hi):
        for a in range(a_lo, a_hi):
            part[a - a_lo] += y[k, a]
        if (k - k_lo) % BLOCK == BLOCK - 1 or k == k_hi - 1:
            total += part
            part[:] = 0.0
    return total


@jit(nogil=True)
def _integrate(y, a_lo, a_hi, mean, k_lo, k_hi, x):  # pragma: no cover - compiled
    # x[a - a_lo, k + 1] = sum_{j=k_lo..k} (y[j, a] - mean[a - a_lo]), the running sum of
    # each axis in order.  Rows in blocks of BLOCK (in L2), each axis's running sum over the
    # block in a register: one pass over the samples from memory, and no store-to-load
    # round trip of the running value per sample (2-3x faster than axis-inner order).
    run = np.zeros(a_hi - a_lo)
    for k0 in range(k_lo, k_hi, BLOCK):
        k1 = min(k0 + BLOCK, k_hi)
        for a in range(a_lo, a_hi):
            r = run[a - a_lo]
            mu = mean[a - a_lo]
            row = x[a - a_lo]
            for k in range(k0, k1):
                r += y[k, a] - mu
                row[k + 1] = r
            run[a - a_lo] = r


def _cuts(n, parts):
    return [n * c // parts for c in range(parts + 1)]


def column_means(y):
    """Mean of every column of ``y`` (n, A), float64 C-contiguous: one row-major pass."""
    cut = _cuts(y.shape[0], 2)
    sums = map_threads(lambda c: _column_sums(y, 0, y.shape[1], cut[c], cut[c + 1]), [0, 1])
    return (sums[0] + sums[1]) / y.shape[0]


def phase(data, a_lo=0, a_hi=None, means=None):
    """
    Phase (A, n + 1) of rate samples (n, A), de-meaned, x_0 = 0: as ``allan._phase``.

    Of the axes ``a_lo:a_hi`` only (all by default); ``means``: the column means of all axes
    (:func:`column_means` when not given).  Two ranges of rows integrated on two threads, then
    the first range's end value added to the second (a start value from the column sums would
    carry their rounding as a step into the phase).
    """
    y = np.ascontiguousarray(data, dtype=np.float64)
    n = y.shape[0]
    a_hi = y.shape[1] if a_hi is None else a_hi
    cut = _cuts(n, 2)
    mean = np.ascontiguousarray((column_means(y) if means is None else means)[a_lo:a_hi])
    x = np.empty((a_hi - a_lo, n + 1))
    x[:, 0] = 0.0
    map_threads(lambda c: _integrate(y, a_lo, a_hi, mean, cut[c], cut[c + 1], x), [0, 1])
    x[:, cut[1] + 1:] += x[:, cut[1]:cut[1] + 1]
    return x


@jit(nogil=True)
def _pairwise_rows(flat, cols, lo, n, r):  # pragma: no cover - compiled; tested vs numpy
    # Column sums of rows lo .. lo + n - 1 of the C-ordered (rows, cols) array ``flat`` by
    # numpy's pairwise summation (pairwise_sum, numpy/_core/src/umath/loops_utils.h: eight
    # accumulators up to 128 values, halves split at a multiple of 8 above), every column at
    # once: the same additions in the same order as ``y[:, a].sum()``, in one pass over rows.
    out = np.zeros(cols)
    if n < 8:
        for i in range(lo, lo + n):
            for a in range(cols):
                out[a] += flat[i * cols + a]
        return out
    if n <= 128:
        w = 8 * cols  # eight consecutive rows: the eight accumulators of every column
        base = lo * cols
        for k in range(w):
            r[k] = flat[base + k]
        stop = lo + n - n % 8
        for i in range(lo + 8, stop, 8):
            rows = flat[i * cols:i * cols + w]
            for k in range(w):
                r[k] += rows[k]
        for a in range(cols):
            out[a] = (((r[a] + r[cols + a]) + (r[2 * cols + a] + r[3 * cols + a]))
                      + ((r[4 * cols + a] + r[5 * cols + a])
                         + (r[6 * cols + a] + r[7 * cols + a])))
        for i in range(stop, lo + n):
            for a in range(cols):
                out[a] += flat[i * cols + a]
        return out
    n2 = n // 2
    n2 -= n2 % 8
    return (_pairwise_rows(flat, cols, lo, n2, r)
            + _pairwise_rows(flat, cols, lo + n2, n - n2, r))


def means_exact(y):
    """
    Column means of ``y`` (n, A), float64 C-contiguous, bit for bit ``y[:, a].mean()``.

    numpy sums a column by its pairwise summation over a strided view: one pass over all the
    samples per column (six for an IMU).  Here the same tree of additions runs over rows, all
    columns at once, its two top halves on two threads (numpy adds them last, too).
    """
    n, cols = y.shape
    flat = y.reshape(-1)
    if n <= 128:
        return _pairwise_rows(flat, cols, 0, n, np.empty(8 * cols)) / n
    n2 = n // 2
    n2 -= n2 % 8
    halves = map_threads(lambda h: _pairwise_rows(flat, cols, (0, n2)[h], (n2, n - n2)[h],
                                                  np.empty(8 * cols)), [0, 1])
    return (halves[0] + halves[1]) / n


def phase_exact(data):
    """
    Phase (A, n + 1) of rate samples (n, A), bit for bit ``allan._phase``: one compiled pass.

    numpy's operations in numpy's order (:func:`means_exact`, then one running sum per axis),
    without its copies: for estimators whose recursions carry the phase's rounding into the
    result (the MDEV running sum: 1e-11 relative between :func:`phase` and numpy's).
    """
    y = np.ascontiguousarray(data, dtype=np.float64)
    means = means_exact(y)
    x = np.empty((y.shape[1], y.shape[0] + 1))
    x[:, 0] = 0.0
    _integrate(y, 0, y.shape[1], means, 0, y.shape[0], x)
    return x


#: Axes integrated and summed together.  One at a time, the phase holds a sixth of the
#: record's size instead of all of it, so ``analyze`` on 10 h of samples peaks at 1.46x the
#: samples instead of 2x (3 at a time: 1.73x, bench/bench_memory.py); it costs four more
#: strided passes over the samples (the column means are taken once for all axes).
AXIS_GROUP = 1


def avar(data, ms):
    """
    Overlapping AVAR (T, A) of rate samples (n, A): as ``allan.avar_reference``, compiled.

    ``ms``: averaging factors, 1 <= m <= n / 2, any order.
    """
    y = np.ascontiguousarray(data, dtype=np.float64)
    means = column_means(y)  # once: each column's sum does not depend on the others
    return _avar_groups(lambda a_lo, a_hi: phase(y, a_lo, a_hi, means), y.shape[1],
                        y.shape[0] + 1, ms)


def avar_phase(x, ms):
    """
    Overlapping AVAR (T, A) from the phase ``x`` (A, n + 1) of :func:`phase`: as :func:`avar`.

    For callers that hold the phase already (:func:`imu_allan.deviation`): the same numbers
    as :func:`avar` on the samples, without integrating them a second time.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    return _avar_groups(lambda a_lo, a_hi: x[a_lo:a_hi], x.shape[0], x.shape[1], ms)


def _avar_groups(phase_of, n_axes, n_phase, ms):
    """AVAR (T, A) of ``n_axes`` phases of ``n_phase`` points, ``phase_of(a_lo, a_hi)``."""
    ms = np.asarray(ms, dtype=np.int64)
    order = np.argsort(ms)
    sms = np.ascontiguousarray(ms[order])
    if sms.size == 0:
        return np.zeros((0, n_axes))
    if sms[0] < 1 or 2 * sms[-1] > n_phase - 1:
        raise ValueError(f'averaging factors must be in 1 .. {(n_phase - 1) // 2}')
    k_max = n_phase - 2 * int(sms[0])
    chunks = -(-8 // n_axes)  # at least 8 jobs: balance on a shared machine
    cut = _cuts(k_max, chunks)
    part = np.zeros((n_axes, chunks, sms.size))
    for a_lo in range(0, n_axes, AXIS_GROUP):
        a_hi = min(a_lo + AXIS_GROUP, n_axes)
        x = phase_of(a_lo, a_hi)

        def job(index, x=x, a_lo=a_lo):
            a, c = divmod(index, chunks)
            _axis_range(x[a], sms, cut[c], cut[c + 1], part[a_lo + a, c])
        map_threads(job, list(range((a_hi - a_lo) * chunks)))
        del job, x  # before the next group's phase is allocated
    _note_compilation()
    out = np.empty((sms.size, n_axes))
    out[order] = part.sum(axis=1).T / (2.0 * sms * sms * (n_phase - 2 * sms))[:, None]
    return out


_NOTED = []


def _note_compilation():
    """Warn once if the kernel could not be cached in this package's own ``__pycache__``."""
    if _NOTED:
        return
    _NOTED.append(True)
    if UNCACHED:
        _LOG.warning('imu_allan: no writable cache directory for numba (set NUMBA_CACHE_DIR '
                     'to one): the Allan kernel is compiled in every process (~2 s)')
        return
    stats = _axis_range.stats
    own = os.path.join(os.path.dirname(os.path.abspath(__file__)), '__pycache__')
    chosen = os.environ.get('NUMBA_CACHE_DIR')  # the user's choice: nothing to report
    if stats.cache_misses and not chosen and os.path.abspath(stats.cache_path) != own:
        _LOG.warning('imu_allan: compiled the Allan kernel into %s (once: %s is not '
                     'writable)', stats.cache_path, own)
