"""
Compiled lag-1 autocorrelation noise identification (numba), imported by :mod:`.api`.

The same steps as :func:`.noise_id.acf_alpha` on the block means of the phase (Riley &
Greenhall 2004: block means of m samples, a least-squares line removed, lag-1
autocorrelation r1, delta = r1 / (1 + r1), difference while delta >= 0.25 and fewer than
``dmax`` differences were taken, alpha = -round(2 delta) - 2 d), one (axis, m) job per call,
run on the package's thread pool.  numpy spends most of its time there on temporaries and on
OpenBLAS starting threads for each (A, K) dot product (2-8 ms per averaging time on the
shared machine, more than the deviation itself); here one job is two passes over at most
:data:`.noise_id.MAX_POINTS` block means in one work array.  :func:`.noise_id.identify_phase`
with ``fast=False`` is the oracle the tests compare with.
"""

import numpy as np

from .noise_id import b1_alpha, MAX_POINTS, MIN_ACF_POINTS
from ..jit import jit, map_threads


@jit(nogil=True, fastmath=False)
def _acf_alpha(x, m, k, dmax):  # pragma: no cover - compiled; tested vs numpy
    z = np.empty(k)
    for j in range(k):
        z[j] = (x[(j + 1) * m] - x[j * m]) / m  # block means
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


def identify_phase(x, ms, dmax=2, alpha_range=(-2, 2)):
    """:func:`.noise_id.identify_phase`, the ACF steps compiled: alpha (T, A) from x (A, N+1)."""
    x = np.ascontiguousarray(x, dtype=float)
    n = x.shape[1] - 1
    ks = [min(n // int(m), MAX_POINTS) for m in ms]
    jobs = [(t, a) for t, k in enumerate(ks) if k >= MIN_ACF_POINTS
            for a in range(x.shape[0])]

    def run(job):
        t, a = job
        return _acf_alpha(x[a], int(ms[t]), ks[t], dmax)

    acf = dict(zip(jobs, map_threads(run, jobs)))
    out = np.zeros((len(ms), x.shape[0]), dtype=int)
    last = np.zeros(x.shape[0], dtype=int)
    for t, (m, k) in enumerate(zip(ms, ks)):
        m = int(m)
        if k >= MIN_ACF_POINTS:
            last = np.array([acf[(t, a)] for a in range(x.shape[0])], dtype=int)
        elif k >= 3:
            last = b1_alpha(np.diff(x[:, :k * m + 1:m], axis=1) / m)
        out[t] = last
    return np.clip(out, *alpha_range)
