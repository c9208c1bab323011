"""
Compiled sums of the O(N)-per-tau kinds (numba): adev, hdev, ohdev, mdev/tdev, totdev.

No temporaries (numpy makes three to five full-length arrays per averaging time), jobs run on
the package's thread pool (:func:`imu_allan.core.jit.map_threads`).  adev and hdev (stride
m: N / m terms), ohdev and totdev (N terms per m) are summed block by block over the phase,
every averaging time per 32 KiB block, as the Allan kernel (:mod:`..allan_kernel`): each
phase point comes from memory once per axis.  mdev is
Stable32's recursion, one pass per (axis, m).  The numpy versions in
:mod:`.allan_family`, :mod:`.modified` and :mod:`.total` are the oracles these are tested
against.
"""

import numpy as np

from ..jit import jit, map_threads


@jit(nogil=True, fastmath=False)
def _modified_sum(x, m):  # pragma: no cover - compiled; tested vs numpy
    # Stable32's recursion: consecutive inner sums differ by one third difference.
    count = x.shape[0] - 3 * m + 1
    v = 0.0
    for i in range(m):
        v += x[i + 2 * m] - 2.0 * x[i + m] + x[i]
    s = v * v
    # Views indexed from 0: numba then drops its negative-index checks (1.7-2x faster).
    x3, x2, x1 = x[3 * m:], x[2 * m:], x[m:]
    for j in range(count - 1):
        v += x3[j] - 3.0 * x2[j] + 3.0 * x1[j] - x[j]
        s += v * v
    return s, count


#: Phase points per block of the overlapping sums (as :data:`..allan_kernel.BLOCK`: 32 KiB).
BLOCK = 4096


@jit(fastmath=True, nogil=True, inline='never')
def _third_one(xa, m, k0, k1):  # pragma: no cover - compiled; tested vs numpy
    # Views indexed from 0 in a function of their own: the form LLVM vectorises.
    x3, x2, x1, x0 = xa[k0 + 3 * m:], xa[k0 + 2 * m:], xa[k0 + m:], xa[k0:]
    s = 0.0
    for k in range(k1 - k0):
        d = x3[k] - 3.0 * x2[k] + 3.0 * x1[k] - x0[k]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _centred_one(xa, m, i0, i1):  # pragma: no cover - compiled; tested vs numpy
    lo, mid, hi = xa[i0 - m:], xa[i0:], xa[i0 + m:]
    s = 0.0
    for i in range(i1 - i0):
        d = lo[i] - 2.0 * mid[i] + hi[i]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _stride_one(xa, m, d, q0, q1):  # pragma: no cover - compiled; tested vs numpy
    # Squared d-th differences (2: Allan, 3: Hadamard) ending at q = q0, q0 + m, ... < q1,
    # in allan_family's order of operations (x_{k+2m} - 2 x_{k+m} + x_k, and the third).
    s = 0.0
    if d == 2:
        for q in range(q0, q1, m):
            e = xa[q] - 2.0 * xa[q - m] + xa[q - 2 * m]
            s += e * e
    else:
        for q in range(q0, q1, m):
            e = xa[q] - 3.0 * xa[q - m] + 3.0 * xa[q - 2 * m] - xa[q - 3 * m]
            s += e * e
    return s


@jit(nogil=True)
def _stride_blocks(xa, ms, d, acc):  # pragma: no cover - compiled
    # acc[t] += the squared non-overlapping d-th differences at stride ms[t] (adev, hdev):
    # block by block over the phase, every averaging time per block, each difference taken
    # where its last point x_q (q a multiple of m, q >= d m) lies.  One pass per m streamed
    # the whole phase from memory once per m below the cache line (8 points) and touched a
    # new line per term above it; here the block is in L1 and the d m points behind each term
    # in L2 (m up to a block) or few (m beyond it: one term per block at most).
    n = xa.shape[0]
    for b0 in range(0, n, BLOCK):
        b1 = min(b0 + BLOCK, n)
        for t in range(ms.shape[0]):
            m = ms[t]
            q0 = max(d * m, (b0 + m - 1) // m * m)
            if q0 < b1:
                acc[t] += _stride_one(xa, m, d, q0, b1)


@jit(nogil=True)
def _hadamard_blocks(xa, ms, k_lo, k_hi, acc):  # pragma: no cover - compiled
    # acc[t] += sum of squared third differences at ms[t] for k in [k_lo, k_hi), k + 3m < N:
    # block by block, every averaging time per block, so that each phase point comes from
    # memory once and the 3 m window behind it from the caches (as the Allan kernel).
    n_phase = xa.shape[0]
    for k0 in range(k_lo, k_hi, BLOCK):
        k1 = min(k0 + BLOCK, k_hi)
        for t in range(ms.shape[0]):
            k1t = min(k1, n_phase - 3 * ms[t])
            if k1t > k0:
                acc[t] += _third_one(xa, ms[t], k0, k1t)


@jit(nogil=True)
def _total_blocks(xs, ms, i_lo, i_hi, acc):  # pragma: no cover - compiled
    # acc[t] += sum over centres i in [i_lo, i_hi) of (x*_{i-m} - 2 x*_i + x*_{i+m})^2 at
    # ms[t], on the reflected phase x*: block by block, as _hadamard_blocks.
    for i0 in range(i_lo, i_hi, BLOCK):
        i1 = min(i0 + BLOCK, i_hi)
        for t in range(ms.shape[0]):
            acc[t] += _centred_one(xs, ms[t], i0, i1)


@jit(nogil=True)
def _reflect_row(x, out):  # pragma: no cover - compiled; tested vs numpy (total.reflect)
    # total.reflect for one row, written in one pass: x*[mid - j] = 2 x_0 - x_j on the left,
    # x itself in the middle, 2 x_{N-1} - x_{N-1-j} on the right (SP1065 eq 25).
    n = x.shape[0]
    for j in range(1, n - 1):
        out[n - 2 - j] = 2.0 * x[0] - x[j]
    for j in range(n):
        out[n - 2 + j] = x[j]
    for j in range(1, n - 1):
        out[2 * n - 3 + j] = 2.0 * x[n - 1] - x[n - 1 - j]


def _reflect(x):
    """:func:`.total.reflect` (A, 3N - 4), compiled, one row per thread."""
    out = np.empty((x.shape[0], 3 * x.shape[1] - 4))
    map_threads(lambda a: _reflect_row(x[a], out[a]), list(range(x.shape[0])))
    return out


def _blocked(kernel, rows, ms, lo, hi):
    """Run a block kernel on every row of ``rows`` over [lo, hi) in (row, range) jobs: (T, A)."""
    chunks = -(-8 // rows.shape[0])  # at least 8 jobs: balance on a shared machine
    cut = [lo + (hi - lo) * c // chunks for c in range(chunks + 1)]
    part = np.zeros((rows.shape[0], chunks, ms.size))

    def job(index):
        a, c = divmod(index, chunks)
        kernel(rows[a], ms, cut[c], cut[c + 1], part[a, c])
    map_threads(job, list(range(rows.shape[0] * chunks)))
    return part.sum(axis=1).T


def _overlapping(kind, x, ms):
    """OHVAR or TOTVAR (T, A), the overlapping sums blocked over the phase (nan: no term)."""
    n_phase = x.shape[1]
    ms = np.asarray(ms, dtype=np.int64)
    out = np.full((ms.size, x.shape[0]), np.nan)
    if kind == 'ohdev':
        ok = n_phase - 3 * ms >= 1
        if ok.any():
            use = np.ascontiguousarray(ms[ok])
            sums = _blocked(_hadamard_blocks, x, use, 0, n_phase - 3 * int(use.min()))
            out[ok] = sums / (6.0 * use * use * (n_phase - 3 * use))[:, None]
        return out
    ok = (ms <= n_phase - 2) & (n_phase >= 3)
    if ok.any():
        use = np.ascontiguousarray(ms[ok])
        mid = n_phase - 2  # index of x_1 (0-based x[0]) in x*
        sums = _blocked(_total_blocks, _reflect(x), use, mid + 1,
                        mid + n_phase - 1)
        out[ok] = sums / (2.0 * use * use * (n_phase - 2))[:, None]
    return out


def variance(kind, x, ms):
    """Return the adev, hdev, ohdev, mdev (or tdev) or totdev variances (T, A) of x (A, N)."""
    x = np.ascontiguousarray(x, dtype=float)
    if kind in ('ohdev', 'totdev'):
        return _overlapping(kind, x, ms)
    if kind in ('adev', 'hdev'):
        return _strided(kind, x, ms)
    jobs = [(t, a) for t in range(len(ms)) for a in range(x.shape[0])]

    def run(job):
        t, a = job
        m = int(ms[t])
        if x.shape[1] - 3 * m + 1 < 1:  # mdev, tdev
            return np.nan
        s, count = _modified_sum(x[a], m)
        return s / (2.0 * m ** 4 * count)

    out = np.full((len(ms), x.shape[0]), np.nan)
    for (t, a), value in zip(jobs, map_threads(run, jobs)):
        out[t, a] = value
    return out


def _strided(kind, x, ms):
    """AVAR or HVAR, non-overlapping (T, A): one blocked pass per axis (nan: no term)."""
    from .allan_family import SPEC, terms
    d, _, norm = SPEC[kind]
    n_phase = x.shape[1]
    ms = np.asarray(ms, dtype=np.int64)
    out = np.full((ms.size, x.shape[0]), np.nan)
    ok = n_phase - d * ms >= 1
    if ok.any():
        use = np.ascontiguousarray(ms[ok])
        acc = np.zeros((x.shape[0], use.size))
        map_threads(lambda a: _stride_blocks(x[a], use, d, acc[a]), list(range(x.shape[0])))
        count = np.array([terms(kind, n_phase, int(m)) for m in use], dtype=float)
        out[ok] = acc.T / (norm * use * use * count)[:, None]
    return out
