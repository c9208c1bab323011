"""
Exact order statistics of every column of a long record (numba), for Tukey's fences.

``np.percentile`` partitions a copy of each column (introselect: 60-100 ms per column of 3.6 M
samples here), so the quartiles of six axes took 0.5-0.65 s of a 10 h analysis.  This takes
all columns together in three passes over the rows:

1. the minimum and maximum of each column;
2. a histogram of :data:`BINS` equal-width bins between them.  The bin of a value,
   ``int((x - min) * BINS / (max - min))``, never decreases as x grows (each floating-point
   step is monotone), so the k-th smallest value lies in the bin where the running count
   passes k, and its rank inside that bin is known;
3. the values of the bins that hold a wanted rank, gathered and sorted.

The result is the order statistic itself, not an approximation, so quartiles interpolated
from it are numpy's to the bit (:func:`imu_allan.core.checks.preprocess.quartiles`, tested against
``np.percentile``).  Values bunched into few bins (quantised samples, one huge outlier) only
make step 3 sort more.  NaN, infinities or a range that overflows give no answer: the caller
then uses ``np.percentile``.  The columns are split between two threads (the kernel releases
the GIL): 0.15 s instead of 0.25 s for 3.6 M x 6 here.

Compiled once per install (:mod:`.jit`).
"""

import numpy as np

from ..jit import jit, map_threads

#: Histogram bins per column: 512 KiB of counts for six axes, in the L2 cache.
BINS = 1 << 16


@jit(nogil=True)
def _bin(x, lo, scale):  # pragma: no cover - compiled
    b = int((x - lo) * scale)
    return b if b < BINS else BINS - 1


@jit(nogil=True)
def order_stats(data, ranks, out):  # pragma: no cover - compiled; tested against np.sort
    """
    Write the ``ranks``-th smallest values (0-based) of every column of ``data`` into ``out``.

    ``data``: (n, A) float64; ``ranks``: (R,) int64, sorted, in [0, n); ``out``: (A, R).
    Returns False (``out`` undefined) when a column holds NaN or infinity or when its range or
    the bin scale overflows.
    """
    n, a = data.shape
    nr = ranks.shape[0]
    lo = data[0].copy()
    hi = data[0].copy()
    for i in range(n):
        for j in range(a):
            v = data[i, j]
            if v < lo[j]:
                lo[j] = v
            if v > hi[j]:
                hi[j] = v
            if v != v:
                return False
    scale = np.zeros(a)
    for j in range(a):
        width = hi[j] - lo[j]
        if not np.isfinite(width):
            return False
        if width > 0.0:
            scale[j] = BINS / width
            if not np.isfinite(scale[j]):
                return False
    counts = np.zeros((a, BINS), np.int64)
    for i in range(n):
        for j in range(a):
            counts[j, _bin(data[i, j], lo[j], scale[j])] += 1
    # For each wanted rank: its bin and its rank inside the bin; each distinct bin gets a slot
    # of the gather buffer.
    slot = np.full((a, BINS), -1, np.int64)
    where = np.zeros((a, nr), np.int64)     # buffer index of each wanted rank's value
    start = np.zeros(a * nr + 1, np.int64)  # slot s holds buf[start[s]:start[s + 1]]
    fill = np.zeros(a * nr, np.int64)
    nslots = 0
    for j in range(a):
        below = 0
        b = 0
        for q in range(nr):
            while below + counts[j, b] <= ranks[q]:
                below += counts[j, b]
                b += 1
            if slot[j, b] < 0:
                slot[j, b] = nslots
                start[nslots + 1] = start[nslots] + counts[j, b]
                fill[nslots] = start[nslots]
                nslots += 1
            where[j, q] = start[slot[j, b]] + ranks[q] - below
    buf = np.empty(start[nslots])
    for i in range(n):
        for j in range(a):
            v = data[i, j]
            s = slot[j, _bin(v, lo[j], scale[j])]
            if s >= 0:
                buf[fill[s]] = v
                fill[s] += 1
    for s in range(nslots):
        buf[start[s]:start[s + 1]].sort()
    for j in range(a):
        for q in range(nr):
            out[j, q] = buf[where[j, q]]
    return True


def column_order_stats(data, ranks):
    """
    Return the ``ranks``-th smallest values of every column of ``data`` (n, A) as (A, R).

    :func:`order_stats` on the two halves of the columns at once; None where it declines.
    """
    a = data.shape[1]
    out = np.empty((a, len(ranks)))
    cuts = [0, a // 2, a] if a > 1 else [0, a]
    halves = [(data[:, j0:j1], ranks, out[j0:j1]) for j0, j1 in zip(cuts[:-1], cuts[1:])]
    done = map_threads(lambda job: order_stats(*job), halves)
    return out if all(done) else None


@jit(nogil=True)
def outside(data, low, high):  # pragma: no cover - compiled; tested against numpy masks
    """
    Find the values of each column below ``low`` or above ``high`` (per-column bounds).

    Returns ``(counts, rows)``: counts (A,), and the row indices of column j in
    ``rows[sum(counts[:j]):sum(counts[:j + 1])]``, ascending.  NaN is inside, as in numpy
    comparisons.
    """
    n, a = data.shape
    counts = np.zeros(a, np.int64)
    for i in range(n):
        for j in range(a):
            v = data[i, j]
            if v < low[j] or v > high[j]:
                counts[j] += 1
    fill = np.zeros(a, np.int64)
    for j in range(1, a):
        fill[j] = fill[j - 1] + counts[j - 1]
    rows = np.empty(counts.sum(), np.int64)
    if rows.shape[0]:
        for i in range(n):
            for j in range(a):
                v = data[i, j]
                if v < low[j] or v > high[j]:
                    rows[fill[j]] = i
                    fill[j] += 1
    return counts, rows
