"""
Compiled MTOTVAR, HTOTVAR and Theo1 sums (numba), imported by :mod:`.api` on first use.

The three estimators cost O(N m) per averaging factor by definition (every subsequence of 3m
points, or every i with m/2 lags); the numpy versions (:func:`.total.mtotvar`,
:func:`.total.htotvar`, :func:`.theo.theo1_fast`) materialise those windows and are the
oracles these kernels are tested against.  Here each window costs one pass with running
sums (Stable32's MTC.c recursion, as allantools), no temporaries, one (axis, m) job per thread
(:func:`imu_allan.core.jit.map_threads`).

Long records: with ``stride`` > 1 only every stride-th window start (every stride-th i for
Theo1) enters the average, an unbiased estimate of the same expectation from fewer,
still overlapping windows (stride <= m while a window spans 3m points; <= m / 2 for Theo1,
whose terms span m).  :func:`stride_for` picks the smallest stride that keeps a job under
:data:`BUDGET` operations; 1 (the exact estimator) whenever it fits.
"""

import math

import numpy as np

from ..jit import jit, map_threads

#: Operations per (axis, m) job above which window starts are thinned (module docstring).
BUDGET = 3e7


@jit(nogil=True, fastmath=False)
def _total_sum(z, m, stride):  # pragma: no cover - compiled; tested vs numpy
    # Sum over window starts i = 0, stride, ... of mean_j T_j^2 / m^2 for the even-reflected,
    # half-mean-detrended 3m windows of z (MTOTVAR on phase, HTOTVAR on rate).  The 9m-point
    # extension is written once per window as its running sum p (p[t] = e_0 + ... e_{t-1}),
    # so each of the 6m second differences of m-sums costs four loads.
    n = z.shape[0]
    count = n - 3 * m + 1
    half = (3 * m) // 2
    dist = (3 * m + 1) // 2
    p = np.empty(9 * m + 1)
    total = 0.0
    used = 0
    for i in range(0, count, stride):
        s1 = 0.0
        s2 = 0.0
        for k in range(half):
            s1 += z[i + k]
            s2 += z[i + 3 * m - half + k]
        slope = (s2 - s1) / half / dist
        p[0] = 0.0
        for t in range(9 * m):
            if t < 3 * m:
                k = 3 * m - 1 - t
            elif t < 6 * m:
                k = t - 3 * m
            else:
                k = 9 * m - 1 - t
            p[t + 1] = p[t] + (z[i + k] - slope * k)
        acc = 0.0
        for j in range(6 * m):
            d = p[j + m] - p[j] - 2.0 * (p[j + 2 * m] - p[j + m]) + p[j + 3 * m] - p[j + 2 * m]
            acc += d * d
        total += acc / (6.0 * m) / (m * m)
        used += 1
    return total, used


@jit(nogil=True, fastmath=False)
def _theo1_sum(x, m, stride):  # pragma: no cover - compiled; tested vs numpy
    n = x.shape[0]
    h = m // 2
    count = n - m
    weight = np.empty(h)
    for delta in range(h):
        weight[delta] = 1.0 / (h - delta)
    total = 0.0
    used = 0
    for i in range(0, count, stride):
        u = x[i] + x[i + m]
        s = 0.0
        for delta in range(h):
            a = u - x[i + h - delta] - x[i + h + delta]
            s += a * a * weight[delta]
        total += s
        used += 1
    return total, used


def stride_for(kind, n_phase, m):
    """Window-start stride of ``kind`` at factor ``m``: 1 if the job fits :data:`BUDGET`."""
    if kind == 'theo1':
        work, cap = (n_phase - m) * (m / 2.0), max(1, m // 2)
    else:
        work, cap = (n_phase - 3 * m) * 15.0 * m, max(1, m)
    return int(min(max(1, math.ceil(work / BUDGET)), cap))


def variance(kind, x, ms, strides=None):
    """
    MTOTVAR, HTOTVAR (uncorrected) or Theo1 (T, A) from the phase ``x`` (A, N), compiled.

    ``strides`` (T,) overrides :func:`stride_for` (1: the exact estimator).
    """
    x = np.ascontiguousarray(x, dtype=float)
    y = np.ascontiguousarray(np.diff(x, axis=1)) if kind == 'htotdev' else None
    n_phase = x.shape[1]
    if strides is None:
        strides = [stride_for(kind, n_phase, int(m)) for m in ms]
    jobs = [(t, a, int(m), int(s)) for t, (m, s) in enumerate(zip(ms, strides))
            for a in range(x.shape[0])]

    def run(job):
        t, a, m, s = job
        if kind == 'theo1':
            if m % 2 or m < 2 or m > n_phase - 1:
                return np.nan
            total, used = _theo1_sum(x[a], m, s)
            return total / (0.75 * used * m * m)
        if kind == 'htotdev' and m == 1:
            from .allan_family import variance_reference
            return variance_reference('ohdev', x[a:a + 1], [1])[0, 0]
        z = y[a] if kind == 'htotdev' else x[a]
        if z.shape[0] - 3 * m + 1 < 1:
            return np.nan
        total, used = _total_sum(z, m, s)
        if kind == 'htotdev':
            return total / (6.0 * used)
        return total / (2.0 * m * m * used)

    values = map_threads(run, jobs)
    out = np.full((len(ms), x.shape[0]), np.nan)
    for (t, a, _, _), v in zip(jobs, values):
        out[t, a] = v
    return out
