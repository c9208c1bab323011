"""
Compiled sums of the O(N)-per-tau kinds (numba): adev, hdev, ohdev, mdev/tdev, totdev.

Each (axis, m) job is one pass over the phase with no temporaries (numpy makes three to five
full-length arrays per averaging time), run on the package's thread pool
(:func:`imu_allan.core.jit.map_threads`).  The numpy versions in :mod:`.allan_family`,
:mod:`.modified` and :mod:`.total` are the oracles these are tested against.
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
    for j in range(count - 1):
        v += x[j + 3 * m] - 3.0 * x[j + 2 * m] + 3.0 * x[j + m] - x[j]
        s += v * v
    return s, count


@jit(nogil=True, fastmath=True)
def _total_sum(xs, mid, n_phase, m):  # pragma: no cover - compiled; tested vs numpy
    s = 0.0
    for i in range(mid + 1, mid + n_phase - 1):
        d = xs[i - m] - 2.0 * xs[i] + xs[i + m]
        s += d * d
    return s


def variance(kind, x, ms):
    """Return the adev, hdev, ohdev, mdev (or tdev) or totdev variances (T, A) of x (A, N)."""
    x = np.ascontiguousarray(x, dtype=float)
    n_phase = x.shape[1]
    if kind == 'totdev':
        from .total import reflect
        xs = np.ascontiguousarray(reflect(x))
    jobs = [(t, a, int(m)) for t, m in enumerate(ms) for a in range(x.shape[0])]

    def run(job):
        t, a, m = job
        if kind == 'adev':
            s, count = _allan_sum(x[a], m, m)
            return s / (2.0 * m * m * count) if count else np.nan
        if kind in ('hdev', 'ohdev'):
            s, count = _hadamard_sum(x[a], m, m if kind == 'hdev' else 1)
            return s / (6.0 * m * m * count) if count else np.nan
        if kind in ('mdev', 'tdev'):
            if n_phase - 3 * m + 1 < 1:
                return np.nan
            s, count = _modified_sum(x[a], m)
            return s / (2.0 * m ** 4 * count)
        if m > n_phase - 2 or n_phase < 3:
            return np.nan
        return _total_sum(xs[a], n_phase - 2, n_phase, m) / (2.0 * m * m * (n_phase - 2))

    values = map_threads(run, jobs)
    out = np.full((len(ms), x.shape[0]), np.nan)
    for (t, a, _), v in zip(jobs, values):
        out[t, a] = v
    return out
