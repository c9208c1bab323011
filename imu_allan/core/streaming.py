"""
Bounded-memory online overlapping Allan variance (the estimator the online pipeline runs).

Estimator
---------
The overlapping Allan variance at averaging factor m (tau = m tau0) is a mean of squared second
differences of the phase x (here the cumulative sum of the rate samples, in sample units, so
tau0 cancels):

    AVAR(m) = sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 m^2 K),   K terms   (as in allan.py)

Each new phase point x_j completes exactly one new term per factor m (k = j - 2m), which needs
only the phase 2m points back.  :class:`StreamingAllan` keeps, per *stride level* s = 1, 2, 4,
..., a short history of the phase sampled every s points (exact phase values: sub-sampling
the cumulative sum loses nothing) and running sums of the squared second differences:

* factors m <= ``stride_base`` (default 256) are tracked at stride 1: every term of the batch
  estimator is formed, so the result equals :func:`imu_allan.core.allan.allan_deviation` on
  the same samples (to float rounding, about 1e-13 relative; ``test_online_streaming.py``
  proves it for any chunking);
* a larger factor m is rounded to a multiple of its level's stride s = 2^ceil(log2(m / base)),
  so m / s is between base / 2 and base, and only the terms with k a multiple of s are formed:
  an unbiased estimator of the same Allan variance that uses 1 of every s overlapping terms,
  i.e. still at least base / 2 = 128 offsets per cluster length.  Its variance is within a few
  per cent of the fully overlapping one (measured in docs/online.md);
* with ``exact=True`` every factor uses stride 1 (memory 2 m_max values per axis).

Memory is fixed at construction: per level a phase history of 2 x (largest m / s) points,
per factor one running sum, per window bucket one more; nothing grows with the number of
samples (:meth:`StreamingAllan.memory_bytes`).

Chunk invariance: samples are processed in fixed frames of ``frame`` samples counted from the
start of the stream, and :meth:`StreamingAllan.result` adds the unfinished frame on a copy of
the state, so any chunking of the same samples gives bit-identical results.  That is what makes
the allan node and ``online_allan`` (the offline path of ``analyze``) publish equal numbers.

Gaps: excluded samples (motion) or a stamp gap end the current *segment*: the phase restarts
and no second difference spans the gap.  The result then equals the sum of the per-segment
overlapping sums (the batch estimator applied to each segment, pooled).

Sliding window: with ``window_s`` > 0 the sums are also kept in ``window_buckets`` buckets of
equal length (in stream samples); a term is booked to the bucket of its newest sample, and the
windowed result pools the newest ``window_buckets`` buckets, i.e. the terms that end within the
last (1 - 1/buckets) W to W seconds.
"""

import copy
import math

import numpy as np

from .allan import AllanResult, DEFAULT_MIN_CLUSTERS, DEFAULT_POINTS_PER_DECADE, log_grid
from .units import AXES

DEFAULT_STRIDE_BASE = 256
DEFAULT_MAX_TAU = 10000.0
DEFAULT_FRAME = 1024


def factor_grid(rate_hz, max_tau=DEFAULT_MAX_TAU, points_per_decade=DEFAULT_POINTS_PER_DECADE,
                taus=None, stride_base=DEFAULT_STRIDE_BASE, exact=False):
    """
    Averaging factors and strides the streaming estimator tracks.

    Returns ``(m, stride)`` int arrays (sorted, unique).  ``taus`` (s) replaces the log grid.
    Factors above ``stride_base`` are rounded to a multiple of their stride unless ``exact``.
    """
    if taus is not None:
        ms = np.round(np.atleast_1d(np.asarray(taus, dtype=float)) * rate_hz).astype(np.int64)
        if np.any(ms < 1):
            raise ValueError('an averaging time is shorter than one sample')
    else:
        m_max = int(round(max_tau * rate_hz))
        if m_max < 1:
            raise ValueError('max_tau is shorter than one sample')
        ms = log_grid(m_max, points_per_decade)
    ms = np.unique(ms)
    if exact:
        return ms, np.ones_like(ms)
    base = int(stride_base)
    strides = np.ones_like(ms)
    big = ms > base
    strides[big] = 2 ** np.ceil(np.log2(ms[big] / base)).astype(np.int64)
    ms = np.maximum(np.round(ms / strides).astype(np.int64), 1) * strides
    ms, first = np.unique(ms, return_index=True)
    return ms, strides[first]


class _State:
    """Everything :class:`StreamingAllan` mutates (copied for previews)."""

    def __init__(self, levels, n_factors, n_axes, n_buckets):
        self.hist = [np.zeros((cap, n_axes)) for _, _, _, cap in levels]
        self.fill = [0] * len(levels)
        self.acc = np.zeros((n_factors, n_axes))
        self.cnt = np.zeros(n_factors, dtype=np.int64)
        self.wacc = np.zeros((n_buckets, n_factors, n_axes))
        self.wcnt = np.zeros((n_buckets, n_factors), dtype=np.int64)
        self.bucket = 0          # global index of the newest bucket
        self.phase = np.zeros(n_axes)  # phase at the newest point of the segment (rebased)
        self.seg = -1            # phase index within the current segment; -1: no segment
        self.offset = np.zeros(n_axes)  # constant removed from the samples (AVAR-invariant)
        self.has_offset = False
        self.n_offered = 0       # samples given to the estimator (used or not)
        self.n_used = 0          # samples that entered the estimate
        self.n_segments = 0

    def arrays(self):
        return self.hist + [self.acc, self.cnt, self.wacc, self.wcnt, self.phase, self.offset]


class StreamingAllan:
    """
    Online overlapping Allan variance with fixed memory (see the module docstring).

    Parameters
    ----------
    rate_hz : float
        Sample rate, Hz (tau0 = 1 / rate_hz).
    axes : sequence of str
        Column names (default the six package axes).
    max_tau : float
        Longest averaging time tracked, s (fixes the memory).
    points_per_decade : float
        Density of the log grid of averaging factors.
    taus : array_like, optional
        Explicit averaging times, s (replace the grid).
    stride_base : int
        Largest factor tracked at stride 1 (exact); larger factors use strides (see above).
    exact : bool
        Track every factor at stride 1 (memory 2 x m_max values per axis).
    window_s : float
        Sliding-window length, s (0: no window).
    window_buckets : int
        Buckets per window (the window's time resolution is window_s / window_buckets).
    frame : int
        Samples per processing frame (see chunk invariance above).
    min_clusters : int
        A factor is reported once its data span at least ``min_clusters`` x m samples (the
        batch estimator's tau_max = T / 10 rule).

    """

    def __init__(self, rate_hz, axes=AXES, max_tau=DEFAULT_MAX_TAU,
                 points_per_decade=DEFAULT_POINTS_PER_DECADE, taus=None,
                 stride_base=DEFAULT_STRIDE_BASE, exact=False, window_s=0.0, window_buckets=16,
                 frame=DEFAULT_FRAME, min_clusters=DEFAULT_MIN_CLUSTERS):
        if not rate_hz or not math.isfinite(rate_hz) or rate_hz <= 0:
            raise ValueError('rate_hz must be a positive number')
        if stride_base < 1 or frame < 1 or window_buckets < 1 or window_s < 0:
            raise ValueError('stride_base, frame, window_buckets must be >= 1, window_s >= 0')
        self.rate_hz = float(rate_hz)
        self.axes = tuple(axes)
        n_axes = len(self.axes)
        self.ms, self.strides = factor_grid(self.rate_hz, max_tau, points_per_decade, taus,
                                            stride_base, exact)
        self.min_clusters = int(min_clusters)
        # Levels: (stride, factor indices, m / stride, history capacity).
        self._levels = []
        for s in np.unique(self.strides):
            idx = np.flatnonzero(self.strides == s)
            qs = self.ms[idx] // s
            self._levels.append((int(s), idx, qs, int(2 * qs.max())))
        self.window_s = float(window_s)
        n_buckets = int(window_buckets) if window_s > 0 else 1
        self._bucket_len = (max(1, int(math.ceil(window_s * rate_hz / n_buckets)))
                            if window_s > 0 else None)
        self._st = _State(self._levels, self.ms.size, n_axes, n_buckets)
        self.frame = int(frame)
        self._pend = np.zeros((self.frame, n_axes))
        self._pend_use = np.zeros(self.frame, bool)
        self._pend_brk = np.zeros(self.frame, bool)
        self._pend_n = 0

    # -- bookkeeping -------------------------------------------------------------------------

    @property
    def n_used(self):
        """Return the samples in the estimate (committed frames plus the unfinished one)."""
        return self._st.n_used + int(self._pend_use[:self._pend_n].sum())

    @property
    def n_offered(self):
        """Return the samples given to :meth:`update`, used or not."""
        return self._st.n_offered + self._pend_n

    def memory_bytes(self):
        """Bytes held in numpy buffers: fixed at construction, independent of run length."""
        return (sum(a.nbytes for a in self._st.arrays()) + self._pend.nbytes
                + self._pend_use.nbytes + self._pend_brk.nbytes)

    # -- input -------------------------------------------------------------------------------

    def update(self, block, use=None, break_before=None):
        """
        Add rate samples.

        Parameters
        ----------
        block : array_like
            Shape (n, A) (or (n,) for one axis), SI units.
        use : array_like of bool, optional
            False for samples to leave out (motion); a left-out run ends the segment.
        break_before : array_like of bool, optional
            True where the phase must restart before the sample (a stamp gap).

        """
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        n = block.shape[0]
        if block.shape[1] != len(self.axes):
            raise ValueError(f'expected {len(self.axes)} columns, got {block.shape[1]}')
        use = np.ones(n, bool) if use is None else np.asarray(use, bool)
        brk = np.zeros(n, bool) if break_before is None else np.asarray(break_before, bool)
        i = 0
        while i < n:
            take = min(self.frame - self._pend_n, n - i)
            j = self._pend_n
            self._pend[j:j + take] = block[i:i + take]
            self._pend_use[j:j + take] = use[i:i + take]
            self._pend_brk[j:j + take] = brk[i:i + take]
            self._pend_n += take
            i += take
            if self._pend_n == self.frame:
                self._process(self._st, self._pend, self._pend_use, self._pend_brk)
                self._pend_n = 0

    # -- processing --------------------------------------------------------------------------

    def _advance_bucket(self, st, target):
        if self._bucket_len is None or target <= st.bucket:
            return
        n_b = st.wcnt.shape[0]
        for b in range(st.bucket + 1, min(target, st.bucket + n_b) + 1):
            st.wacc[b % n_b] = 0.0
            st.wcnt[b % n_b] = 0
        st.bucket = target

    def _process(self, st, data, use, brk):
        n = data.shape[0]
        if n == 0:
            return
        g0 = st.n_offered
        if not st.has_offset and use.any():
            # Removing a constant leaves AVAR unchanged and keeps the phase small.
            st.offset[:] = data[use].mean(axis=0)
            st.has_offset = True
        stops = ~use | brk
        if self._bucket_len is not None:
            pos = np.arange(n)
            stops = stops | ((g0 + pos) % self._bucket_len == 0)
        stop_idx = np.flatnonzero(stops)
        i = 0
        while i < n:
            if brk[i] or not use[i]:
                st.seg = -1
            if not use[i]:
                nxt = np.flatnonzero(use[i:])
                if nxt.size == 0:
                    break
                i += int(nxt[0])
                continue
            later = stop_idx[np.searchsorted(stop_idx, i, side='right'):]
            j = int(later[0]) if later.size else n
            if self._bucket_len is not None:
                self._advance_bucket(st, (g0 + i) // self._bucket_len)
            self._feed_run(st, data[i:j])
            i = j
        st.n_offered += n
        st.n_used += int(use.sum())
        if self._bucket_len is not None:
            self._advance_bucket(st, (st.n_offered - 1) // self._bucket_len)

    def _feed_run(self, st, samples):
        """Add a run of consecutive used samples to the current segment (or a new one)."""
        if st.seg < 0:
            st.seg = 0
            st.phase[:] = 0.0
            st.n_segments += 1
            for li in range(len(self._levels)):
                st.hist[li][0] = 0.0  # x_0 = 0: phase index 0 is a multiple of every stride
                st.fill[li] = 1
        r = samples.shape[0]
        phase = st.phase + np.cumsum(samples - st.offset, axis=0)  # indices seg+1 .. seg+r
        seg = st.seg
        slot = st.bucket % st.wcnt.shape[0]
        windowed = self._bucket_len is not None
        for li, (s, fidx, qs, cap) in enumerate(self._levels):
            first = (seg // s + 1) * s
            if first > seg + r:
                continue
            new = phase[first - seg - 1:r:s]
            h = st.fill[li]
            x = np.concatenate((st.hist[li][:h], new))
            length = x.shape[0]
            for f, q in zip(fidx, qs):
                k0 = max(0, h - 2 * q)
                k1 = length - 2 * q
                if k1 <= k0:
                    continue
                d = x[k0 + 2 * q:k1 + 2 * q] - 2.0 * x[k0 + q:k1 + q] + x[k0:k1]
                ss = np.einsum('ij,ij->j', d, d)
                st.acc[f] += ss
                st.cnt[f] += k1 - k0
                if windowed:
                    st.wacc[slot, f] += ss
                    st.wcnt[slot, f] += k1 - k0
            keep = min(length, cap)
            st.hist[li][:keep] = x[length - keep:]
            st.fill[li] = keep
        # Rebase: second differences ignore a constant, so shift every stored phase by the
        # newest one; the phase then never grows with run time (no loss of float precision).
        shift = phase[-1].copy()
        for li in range(len(self._levels)):
            st.hist[li][:st.fill[li]] -= shift
        st.phase[:] = 0.0
        st.seg = seg + r

    # -- output ------------------------------------------------------------------------------

    def _current_state(self):
        """Return the state with the unfinished frame (on a copy; the committed one is kept)."""
        if self._pend_n == 0:
            return self._st
        st = copy.deepcopy(self._st)
        n = self._pend_n
        self._process(st, self._pend[:n], self._pend_use[:n], self._pend_brk[:n])
        return st

    def sums(self, window=False):
        """
        Raw running sums: ``(m, stride, sum_sq (F, A), count (F,))`` in sample units.

        ``sum_sq[f] / (2 m^2 count[f])`` is the Allan variance in the samples' unit squared.
        """
        st = self._current_state()
        if window:
            if self._bucket_len is None:
                raise ValueError('no sliding window configured (window_s = 0)')
            return self.ms, self.strides, st.wacc.sum(axis=0), st.wcnt.sum(axis=0)
        return self.ms, self.strides, st.acc.copy(), st.cnt.copy()

    def snapshot(self, window=False, min_clusters=None):
        """
        Return the reportable factors now: ``(m, avar (T, A), n_eff (T,))``, or None.

        Only factors whose data span ``min_clusters`` x m samples are included.  ``n_eff`` is
        the span each factor's terms cover (count x stride + 2m - 1 samples), used as the
        record length for the EDF.  AVAR in the samples' unit squared.
        """
        ms, strides, acc, cnt = self.sums(window)
        min_clusters = self.min_clusters if min_clusters is None else int(min_clusters)
        n_eff = cnt * strides + 2 * ms - 1
        sel = (cnt > 0) & (n_eff >= min_clusters * ms)
        if not sel.any():
            return None
        m = ms[sel]
        avar = acc[sel] / (2.0 * (m * m * cnt[sel]).astype(float))[:, None]
        return m, avar, n_eff[sel]

    def result_from(self, snapshot, columns=None):
        """Build an AllanResult (EDF, intervals) of a :meth:`snapshot`, optionally some columns."""
        if snapshot is None:
            return None
        m, avar, n_eff = snapshot
        columns = range(len(self.axes)) if columns is None else columns
        columns = list(columns)
        return AllanResult.from_avar(m, avar[:, columns], n_eff[:, None], self.rate_hz,
                                     [self.axes[j] for j in columns])

    def result(self, window=False, min_clusters=None):
        """
        Allan deviation of everything seen (or of the sliding window) as an AllanResult.

        None when no factor has enough data yet (see :meth:`snapshot`).
        """
        return self.result_from(self.snapshot(window, min_clusters))
