"""
Compiled sums of the O(N)-per-tau kinds (numba): adev, hdev, ohdev, mdev/tdev, totdev.

No temporaries (numpy makes three to five full-length arrays per averaging time), jobs run on
the package's thread pool (:func:`imu_allan.core.jit.map_threads`).  adev and hdev (stride
m: N / m terms) are one pass per (axis, m); ohdev and totdev (N terms per m) are summed block
by block over the phase, every averaging time per 32 KiB block, as the Allan kernel
(:mod:`..allan_kernel`): each phase point comes from memory once per axis.  mdev is
Stable32's recursion, one pass per (axis, m).  The numpy versions in
:mod:`.allan_family`, :mod:`.modified` and :mod:`.total` are the oracles these are tested
against.
"""

import numpy as np

from ..jit import jit, map_threads


@jit(nogil=True, fastmath=True)
def _allan_sum(x, m, stride):  # pragma: no cover - compiled; tested vs numpy
    s = 0.0
    count = 0
    for k in range(0, x.shape[0] - 2 * m, stride):
        d = x[k + 2 * m] - 2.0 * x[k + m] + x[k]
        s += d * d
        count += 1
    return s, count


@jit(nogil=True, fastmath=True)
def _hadamard_sum(x, m, stride):  # pragma: no cover - compiled; tested vs numpy
    s = 0.0
    count = 0
    for k in range(0, x.shape[0] - 3 * m, stride):
        d = x[k + 3 * m] - 3.0 * x[k + 2 * m] + 3.0 * x[k + m] - x[k]
        s += d * d
        count += 1
    return s, count


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
    # One job per axis over all factors: the strided adev/hdev sums are short (N / m terms
    # each; all factors together about 3 N), so one job per (axis, m) cost more in thread
    # hand-offs than in sums.  mdev's one pass per (axis, m) is long enough to split so.
    if kind in ('adev', 'hdev'):
        jobs = [(None, a) for a in range(x.shape[0])]
    else:
        jobs = [(t, a) for t in range(len(ms)) for a in range(x.shape[0])]

    def one(a, m):
        if kind == 'adev':
            s, count = _allan_sum(x[a], m, m)
            return s / (2.0 * m * m * count) if count else np.nan
        if kind == 'hdev':
            s, count = _hadamard_sum(x[a], m, m)
            return s / (6.0 * m * m * count) if count else np.nan
        if x.shape[1] - 3 * m + 1 < 1:  # mdev, tdev
            return np.nan
        s, count = _modified_sum(x[a], m)
        return s / (2.0 * m ** 4 * count)

    def run(job):
        t, a = job
        if t is None:
            return [one(a, int(m)) for m in ms]
        return [one(a, int(ms[t]))]

    out = np.full((len(ms), x.shape[0]), np.nan)
    for (t, a), values in zip(jobs, map_threads(run, jobs)):
        out[slice(None) if t is None else slice(t, t + 1), a] = values
    return out
