"""
Preprocessing from the thesis, as options: outliers, time-stamp checks, unit conversion.

* Tukey's fences (thesis section 4.2): a sample below Q1 - F IQR or above Q3 + F IQR (F = 3,
  "extreme" outliers) is replaced by the mean of the inliers of its axis, as the thesis does;
  the count per axis is returned so nothing is replaced silently.
* Time stamps: the sample rate comes from the median interval; gaps (an interval longer than
  1.5 nominal intervals), jitter (std of the intervals relative to nominal) and non-increasing
  stamps are reported.  The Allan estimator assumes even spacing, so callers decide whether a
  record with gaps is acceptable.
"""

from dataclasses import dataclass, field

import numpy as np

TUKEY_F = 3.0
GAP_FACTOR = 1.5


@dataclass
class OutlierReport:
    """What :func:`replace_outliers` changed: counts and indices per axis."""

    counts: dict = field(default_factory=dict)
    indices: dict = field(default_factory=dict)
    fences: dict = field(default_factory=dict)
    replaced: bool = False  # True only when the caller asked for the replacement and it happened

    @property
    def total(self):
        """Return the samples replaced over all axes."""
        return int(sum(self.counts.values()))


#: Rows from which :func:`quartiles` uses the compiled order statistics: below, numpy's
#: percentile takes under 0.1 s, less than loading numba would in a process without it.
KERNEL_ROWS = 1 << 20


def _kernels(n):
    """Return :mod:`.quantile_kernel` for a record of ``n`` rows, or None (numpy instead)."""
    if n < KERNEL_ROWS:
        return None
    try:
        from . import quantile_kernel
    except ImportError:     # numba is optional: numpy gives the same numbers, slower
        return None
    return quantile_kernel


def quartiles(data):
    """
    Return Q1 and Q3 of every column of ``data`` (n, A) as an (A, 2) array, in its units.

    Exactly ``np.percentile(data, [25, 75], axis=0).T`` (linear interpolation between order
    statistics, numpy's formula); long records take the two order statistics around each
    quartile from :mod:`.quantile_kernel` (three passes over the rows instead of a partition
    of each column), when numba is available.
    """
    data = np.asarray(data, dtype=float)
    n = data.shape[0]
    kernels = _kernels(n)
    if kernels is not None:
        index = (n - 1) * np.array([0.25, 0.75])    # numpy's "linear" virtual index
        below = np.floor(index)
        ranks = np.stack([below, np.minimum(below + 1, n - 1)], axis=1).astype(np.int64)
        stats = kernels.column_order_stats(data, ranks.ravel())
        if stats is not None:
            a, b = stats[:, 0::2], stats[:, 1::2]
            gamma = index - below
            diff = b - a
            # numpy's _lerp: from the nearer end, so that gamma 0 or 1 give a or b exactly
            return np.where(gamma >= 0.5, b - diff * (1 - gamma), a + diff * gamma)
    return np.percentile(data, [25.0, 75.0], axis=0).T


def outside_rows(data, low, high):
    """
    Return the row indices (ascending) of the values outside [low[j], high[j]], per column j.

    One pass over the rows for all columns (compiled for long records, else numpy masks).
    """
    kernels = _kernels(data.shape[0])
    if kernels is not None and data.dtype == np.float64:
        counts, rows = kernels.outside(data, np.asarray(low, float), np.asarray(high, float))
        return np.split(rows, np.cumsum(counts)[:-1])
    outside = (data < low) | (data > high)
    return [np.flatnonzero(outside[:, j]) for j in range(data.shape[1])]


def tukey_fences(values, f=TUKEY_F):
    """
    Return the lower and upper Tukey fences ``Q1 - f IQR`` and ``Q3 + f IQR``.

    Of ``values`` (n,) as two floats, or of each column of ``values`` (n, A) as two arrays.
    """
    q1, q3 = quartiles(np.reshape(values, (len(values), -1))).T
    iqr = q3 - q1
    lo, hi = q1 - f * iqr, q3 + f * iqr
    return (lo[0], hi[0]) if np.ndim(values) == 1 else (lo, hi)


def replace_outliers(data, axes, f=TUKEY_F, replace=True):
    """
    Find Tukey outliers in ``data`` (n, A); return (data, :class:`OutlierReport`).

    With ``replace`` the data returned is a copy with the outliers replaced by the inlier
    mean; without, ``data`` itself (only counted: no copy of a long record).
    """
    data = np.array(data, dtype=float, copy=replace)
    report = OutlierReport()
    low, high = tukey_fences(data, f)
    for j, (axis, bad) in enumerate(zip(axes, outside_rows(data, low, high))):
        report.fences[axis] = (float(low[j]), float(high[j]))
        report.counts[axis] = len(bad)
        report.indices[axis] = bad
        if replace and 0 < len(bad) < len(data):
            col = data[:, j]
            keep = np.ones(len(col), bool)
            keep[bad] = False
            col[bad] = col[keep].mean()
    return data, report


@dataclass
class TimingReport:
    """Sample-time statistics of a record."""

    rate_hz: float
    nominal_dt: float
    duration_s: float
    n_gaps: int
    longest_gap_s: float
    missing_samples: int
    jitter: float
    n_nonincreasing: int
    gap_indices: np.ndarray


def count_gaps(steps, nominal, gap_factor=GAP_FACTOR):
    """
    Which sample spacings are gaps, and how many samples the gaps lost.

    ``steps`` are spacings (any unit: s, device ticks) and ``nominal`` the regular spacing in
    the same unit; a spacing above ``gap_factor`` x nominal is a gap that lost
    round(step / nominal) - 1 samples.  Returns ``(gap mask, missing samples)``.  The one
    rule for time stamps, raw captures and the live device link.
    """
    steps = np.asarray(steps, dtype=float)
    gaps = steps > gap_factor * nominal
    missing = int(np.sum(np.round(steps[gaps] / nominal) - 1)) if gaps.any() else 0
    return gaps, missing


def nominal_interval(steps, share=0.15, tolerance=0.1, max_factor=8):
    """
    Return the sample interval of a record from its positive time steps (any unit).

    The median step, unless lost samples made most steps a multiple of the true interval (a
    damaged capture losing half its packets steps by 2, 3 ... intervals): then the largest
    divisor k <= ``max_factor`` of the median such that at least ``share`` of the steps lie
    within ``tolerance`` of median / k gives the interval (the median of those steps).
    """
    steps = np.asarray(steps, dtype=float)
    # one scratch array of the record's length (partitioned for the median, then reused for
    # the distances): a 10 h record's steps are 29 MB, and each temporary costs that much
    work = steps.copy()
    median = float(np.median(work, overwrite_input=True))
    # Every step within tolerance of median / k (k >= 2) is at most (1 + tolerance) median / 2:
    # when fewer than ``share`` are, no k can qualify (the usual record: one pass, not seven).
    below = (1.0 + tolerance) * median / 2.0 * (1.0 + 1e-9)
    if np.count_nonzero(steps <= below) < share * steps.size:
        return median
    for k in range(max_factor, 1, -1):
        np.subtract(steps, median / k, out=work)
        near = np.abs(work, out=work) <= tolerance * median / k
        if np.count_nonzero(near) >= share * steps.size:
            return float(np.median(steps[near]))
    return median


def check_timing(t, gap_factor=GAP_FACTOR):
    """
    Analyse time stamps ``t`` (s): rate, gaps, jitter and non-increasing steps.

    ``missing_samples`` estimates how many samples the gaps lost; ``jitter`` is the std of
    the regular intervals divided by the nominal interval.
    """
    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    if dt.size == 0:
        raise ValueError('need at least two samples to know the sample rate')
    increasing = dt > 0
    n_increasing = int(np.count_nonzero(increasing))
    if n_increasing == 0:
        raise ValueError('time stamps never increase')
    # selections copy only when they drop something (the usual clean record: no copy)
    nominal = nominal_interval(dt if n_increasing == dt.size else dt[increasing])
    gaps, missing = count_gaps(dt, nominal, gap_factor)
    regular = increasing & ~gaps
    regular = dt if regular.all() else dt[regular]
    jitter = float(np.std(regular) / nominal) if regular.size else 0.0
    return TimingReport(
        rate_hz=1.0 / nominal, nominal_dt=nominal, duration_s=float(t[-1] - t[0]) + nominal,
        n_gaps=int(gaps.sum()), longest_gap_s=float(dt[gaps].max()) if gaps.any() else 0.0,
        missing_samples=missing, jitter=jitter, n_nonincreasing=int(np.count_nonzero(dt <= 0)),
        gap_indices=np.flatnonzero(gaps))
