"""
Bounded-memory online overlapping Allan variance (the estimator the online pipeline runs).

Measurements, memory figures and the tests behind each claim: docs/online.md, "The online
estimator" and "Modified Allan and overlapping Hadamard deviations".

Estimator: with the phase x the cumulative sum of the rate samples (sample units, so tau0
cancels),

    AVAR(m) = sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 m^2 K),   K terms   (as in allan.py)

Each new phase point completes one new term per factor m, which needs only the phase 2m points
back.  :class:`StreamingAllan` keeps, per *stride level* s = 1, 2, 4, ..., a short history of
the phase sampled every s points (exact: sub-sampling a cumulative sum loses nothing) and
running sums of the squared second differences:

* factors m <= ``stride_base`` (256) use stride 1: every term of the batch estimator, so the
  result equals :func:`imu_allan.core.allan.estimate.allan_deviation` to float rounding;
* a larger m is rounded to a multiple of s = 2^ceil(log2(m / base)) and only the terms with k
  a multiple of s are formed: an unbiased estimator of the same AVAR from 1 of every s terms,
  still at least base / 2 offsets per cluster length;
* ``exact=True``: stride 1 for every factor (memory 2 m_max values per axis).

Memory is fixed at construction (:meth:`StreamingAllan.memory_bytes`): per level a phase
history of 2 x (largest m / s) points, per factor and window bucket one running sum.

Chunk invariance: samples are processed in fixed frames of ``frame`` samples counted from the
start of the stream, and the unfinished frame is added on a copy of the state, so any chunking
gives bit-identical results: the allan node and ``online_allan`` publish equal numbers.

Gaps: an excluded sample (motion, a rejected value) or a stamp gap ends the current *segment*:
the phase restarts and no difference spans it, so the result pools the per-segment sums.
Masks may be per axis: each axis then has its own segments and term counts (NaN where it has
too little data).  A run of some axes only is still computed on every column (the others'
results are discarded), because numpy rounds a column's sum differently for different numbers
of columns: an axis's numbers are bit-identical whatever the other axes left out.

Modified and Hadamard variances (``estimators``) in the same pass:

    OHVAR(m) = sum_k (x_{k+3m} - 3 x_{k+2m} + 3 x_{k+m} - x_k)^2 / (6 m^2 K)   (SP1065 eq. 18)
    MVAR(m) = sum_j (sum_{i=j}^{j+m-1} (x_{i+2m} - 2 x_{i+m} + x_i))^2 / (2 m^4 K')   (eq. 14)

The inner sum of MVAR is the third difference at lag m of S, the cumulative sum of the phase
(S_0 = 0, S_{n+1} = S_n + x_n), so MVAR streams like OHVAR on S, with its own history of S per
level.  K = N + 1 - 3m, K' = N + 2 - 3m for N samples (allantools' counts).  Precision: S of a
raw stream grows like n^2 (1 g, 10^7 samples: 5e14).  The phase is kept relative to its newest
value, and S relative to its newest value and to the line whose slope is the phase shift
removed so far: a third difference ignores both, S keeps the recurrence on the shifted phase,
and each stored S stays bounded by 3m times the phase excursion over 3m samples.

Sliding window: with ``window_s`` > 0 the sums are also kept in ``window_buckets`` buckets of
equal length (in stream samples); a term is booked to the bucket of its newest sample, and the
windowed result pools the newest buckets: the terms that end within the last
(1 - 1/buckets) W to W seconds.
"""

import bisect
import copy
from dataclasses import dataclass
import math

import numpy as np

from ..allan.estimate import AllanResult, DEFAULT_MIN_CLUSTERS, DEFAULT_POINTS_PER_DECADE, log_grid
from ..units import AXES
from ...errors import InputError

DEFAULT_STRIDE_BASE = 256
DEFAULT_MAX_TAU = 10000.0
DEFAULT_FRAME = 1024

#: The deviations the streaming estimator computes (``estimators``); ``oadev`` is always on.
KINDS = ('oadev', 'mdev', 'ohdev')
# Per kind: (difference order, variance divisor c, power p: var = sum / (c m^p K), samples
# spanned by K stride-1 terms minus K and the span of one term: n_eff = K s + order m + lead).
_SPEC = {'oadev': (2, 2.0, 2, -1), 'ohdev': (3, 6.0, 2, -1), 'mdev': (3, 2.0, 4, -2)}


def parse_estimators(value, where='estimators'):
    """
    Return the kinds of a list or comma-separated string, ``oadev`` first, without repeats.

    Raises InputError naming ``where`` for an unknown kind or a value that is no text.
    """
    if isinstance(value, str):
        names = value.split(',')
    elif isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        names = list(value)
    else:
        raise InputError(where, f'expected a list of names or a comma-separated string, '
                                f'got {value!r}')
    names = [n.strip().lower() for n in names if n.strip()]
    unknown = [n for n in names if n not in KINDS]
    if unknown:
        raise InputError(where, f'unknown estimator(s) {", ".join(unknown)} '
                                f'(streaming: {", ".join(KINDS)})')
    return tuple(k for k in KINDS if k == 'oadev' or k in names)


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

    def __init__(self, levels, n_factors, n_axes, n_buckets, kinds=('oadev',), s_caps=()):
        self.hist = [np.zeros((cap, n_axes)) for _, _, _, cap in levels]
        # MVAR: per level the history of S (cumulative sum of the phase), see the docstring.
        self.shist = [np.zeros((cap, n_axes)) for cap in s_caps]
        # Per kind [acc, cnt, wacc, wcnt]: the running sums of squared differences and their
        # term counts (F, A), and the same per window bucket (B, F, A).
        self.sums = {kind: [np.zeros((n_factors, n_axes)),
                            np.zeros((n_factors, n_axes), dtype=np.int64),
                            np.zeros((n_buckets, n_factors, n_axes)),
                            np.zeros((n_buckets, n_factors, n_axes), dtype=np.int64)]
                     for kind in kinds}
        self.bucket = 0          # global index of the newest bucket
        # Phase index within each axis's current segment (-1: no segment).  The stored phase
        # history of a level holds min(seg // stride + 1, capacity) points of that axis.
        self.seg = np.full(n_axes, -1, dtype=np.int64)
        self.offset = np.zeros(n_axes)  # constant removed from the samples (AVAR-invariant)
        self.has_offset = np.zeros(n_axes, bool)
        self.n_offered = 0       # samples given to the estimator (used or not)
        self.n_used = 0          # samples that entered the estimate on at least one axis
        self.n_used_axes = np.zeros(n_axes, dtype=np.int64)  # per axis
        self.n_segments = np.zeros(n_axes, dtype=np.int64)   # per axis

    def arrays(self):
        return self.hist + self.shist + [a for sums in self.sums.values() for a in sums] + [
            self.seg, self.offset, self.has_offset, self.n_used_axes, self.n_segments]


class StreamingAllan:
    """
    Online overlapping Allan variance with fixed memory (see the module docstring).

    ``rate_hz`` in Hz (tau0 = 1 / rate_hz); ``axes`` the column names; ``max_tau`` (s) the
    longest averaging time tracked (it fixes the memory), or ``taus`` (s) explicit averaging
    times instead of the log grid of ``points_per_decade``; ``stride_base``, ``exact``,
    ``frame``, ``window_s`` (s; 0: no window) and ``window_buckets`` as in the module
    docstring.  A factor is reported once its data span ``min_clusters`` x m samples (the
    batch estimator's tau_max = T / 10 rule).  ``estimators``: the kinds of :data:`KINDS` to
    compute, a list or a comma-separated string (``oadev`` always).
    """

    def __init__(self, rate_hz, axes=AXES, max_tau=DEFAULT_MAX_TAU,
                 points_per_decade=DEFAULT_POINTS_PER_DECADE, taus=None,
                 stride_base=DEFAULT_STRIDE_BASE, exact=False, window_s=0.0, window_buckets=16,
                 frame=DEFAULT_FRAME, min_clusters=DEFAULT_MIN_CLUSTERS,
                 estimators=('oadev',)):
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
        self.kinds = parse_estimators(estimators)
        self._ohdev, self._mdev = 'ohdev' in self.kinds, 'mdev' in self.kinds
        # Levels: (stride, index of its first factor, m / stride ascending, history capacity).
        # The strides grow with m, so each level's factors are consecutive.
        self._levels = []
        for s in np.unique(self.strides):
            idx = np.flatnonzero(self.strides == s)
            assert np.all(np.diff(idx) == 1)
            qs = [int(q) for q in self.ms[idx] // s]
            self._levels.append((int(s), int(idx[0]), qs, (3 if self._ohdev else 2) * max(qs)))
        self._s_caps = [3 * max(qs) for _, _, qs, _ in self._levels] if self._mdev else []
        # s x (cap - 1, ..., 1, 0): index offsets of a full S history from its newest point
        self._s_lags = [s * np.arange(cap - 1, -1, -1)[:, None]
                        for (s, _, _, _), cap in zip(self._levels, self._s_caps)]
        self.window_s = float(window_s)
        self._n_buckets = int(window_buckets) if window_s > 0 else 1
        self._bucket_len = (max(1, int(math.ceil(window_s * rate_hz / self._n_buckets)))
                            if window_s > 0 else None)
        self._st = _State(self._levels, self.ms.size, n_axes, self._n_buckets, self.kinds,
                          self._s_caps)
        self.frame = int(frame)
        self._pend = np.zeros((self.frame, n_axes))
        self._pend_use = np.zeros((self.frame, n_axes), bool)
        self._pend_brk = np.zeros((self.frame, n_axes), bool)
        self._pend_n = 0
        self._pend_mixed = False  # a per-axis mask went into the unfinished frame

    # -- bookkeeping -------------------------------------------------------------------------

    @property
    def n_used(self):
        """Return the samples in the estimate on at least one axis (unfinished frame included)."""
        return self._st.n_used + int(self._pend_use[:self._pend_n].any(axis=1).sum())

    @property
    def n_used_axes(self):
        """Return the samples in the estimate per axis, int array (A,)."""
        return self._st.n_used_axes + self._pend_use[:self._pend_n].sum(axis=0)

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
        Add rate samples ``block`` (n, A), or (n,) for one axis, SI units.

        ``use`` (n,) for whole samples or (n, A) per axis: False for values to leave out
        (motion, a rejected value; never read, may be NaN), which ends that axis's segment.
        ``break_before`` (n,) or (n, A): True where the phase restarts before the sample (a
        stamp gap).
        """
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        n, n_axes = block.shape[0], len(self.axes)
        if block.shape[1] != n_axes:
            raise ValueError(f'expected {n_axes} columns, got {block.shape[1]}')
        # None stays a scalar and a 1-D mask a column: both broadcast to every axis below.
        use = True if use is None else _as_mask(use, n, n_axes, 'use')
        brk = False if break_before is None else _as_mask(break_before, n, n_axes,
                                                          'break_before')
        i = 0
        while i < n:
            take = min(self.frame - self._pend_n, n - i)
            j = self._pend_n
            self._pend[j:j + take] = block[i:i + take]
            self._pend_use[j:j + take] = use if use is True else use[i:i + take]
            self._pend_brk[j:j + take] = brk if brk is False else brk[i:i + take]
            self._pend_mixed |= (use is not True and use.shape[1] > 1) or (
                brk is not False and brk.shape[1] > 1)
            self._pend_n += take
            i += take
            if self._pend_n == self.frame:
                self._process(self._st, self._pend, self._pend_use, self._pend_brk,
                              self._pend_mixed)
                self._pend_n = 0
                self._pend_mixed = False

    # -- processing --------------------------------------------------------------------------

    def _advance_bucket(self, st, target):
        if self._bucket_len is None or target <= st.bucket:
            return
        n_b = self._n_buckets
        for b in range(st.bucket + 1, min(target, st.bucket + n_b) + 1):
            for _, _, wacc, wcnt in st.sums.values():
                wacc[b % n_b] = 0.0
                wcnt[b % n_b] = 0
        st.bucket = target

    @staticmethod
    def _groups(st, use, brk, mixed):
        """
        Split the axes into groups that can be processed together in this frame.

        Axes share a group when their masks over the frame and their segment position are
        equal (then their phase histories are in step).  Returns a list of column selectors:
        ``[slice(None)]`` in the common case (every axis in step: the fast path).
        """
        in_step = (st.seg == st.seg[0]).all()
        if in_step and (not mixed or ((use == use[:, :1]).all() and (brk == brk[:, :1]).all())):
            return [slice(None)]
        groups = {}
        for a in range(use.shape[1]):
            key = (int(st.seg[a]), use[:, a].tobytes(), brk[:, a].tobytes())
            groups.setdefault(key, []).append(a)
        return [np.array(cols) for cols in groups.values()]

    def _process(self, st, data, use, brk, mixed=True):
        """
        Add one frame: ``data`` (n, A), ``use`` and ``brk`` (n, A) bool.

        ``mixed`` False: every column of ``use`` and ``brk`` is known to be the same.
        """
        n = data.shape[0]
        if n == 0:
            return
        g0 = st.n_offered
        for a in ([] if st.has_offset.all() else
                  np.flatnonzero(~st.has_offset & use.any(axis=0))):
            # Removing a constant leaves AVAR unchanged and keeps the phase small.  Per column,
            # so an axis's offset does not depend on what the other axes left out.
            st.offset[a] = data[use[:, a], a].mean()
            st.has_offset[a] = True
        # Pieces of the frame within one window bucket (the whole frame without a window).
        if self._bucket_len is None:
            cuts = [0, n]
        else:
            first = -g0 % self._bucket_len
            cuts = sorted({0, n, *range(first, n, self._bucket_len)})
        groups = self._groups(st, use, brk, mixed)
        if len(groups) > 1:
            # Runs are computed on every column (see _feed_run): left-out values (NaN, inf,
            # 1e300 ...) become 0 so the columns not being stored stay finite.
            data = np.where(use, data, 0.0)
        # Each group's masks are those of its first axis: where its runs stop.
        firsts = [0 if isinstance(cols, slice) else int(cols[0]) for cols in groups]
        stops = [np.flatnonzero(~use[:, c] | brk[:, c]) for c in firsts]
        for p0, p1 in zip(cuts[:-1], cuts[1:]):
            if self._bucket_len is not None:
                self._advance_bucket(st, (g0 + p0) // self._bucket_len)
            for cols, c0, stop_idx in zip(groups, firsts, stops):
                col_use, col_brk = use[:, c0], brk[:, c0]
                i = p0
                while i < p1:
                    if col_brk[i] or not col_use[i]:
                        st.seg[cols] = -1
                    if not col_use[i]:
                        nxt = np.flatnonzero(col_use[i:p1])
                        if nxt.size == 0:
                            break
                        i += int(nxt[0])
                        continue
                    later = stop_idx[np.searchsorted(stop_idx, i, side='right'):]
                    j = min(int(later[0]), p1) if later.size else p1
                    self._feed_run(st, data[i:j], cols)
                    i = j
        st.n_offered += n
        if mixed:
            st.n_used += int(use.any(axis=1).sum())
            st.n_used_axes += use.sum(axis=0)
        else:
            used = int(np.count_nonzero(use[:, 0]))
            st.n_used += used
            st.n_used_axes += used
        if self._bucket_len is not None:
            self._advance_bucket(st, (st.n_offered - 1) // self._bucket_len)

    def _feed_run(self, st, samples, cols):
        """
        Add a run of consecutive used samples of the axes ``cols`` to their current segment.

        ``samples`` has every axis (r, A); ``cols`` is ``slice(None)`` (every axis) or an index
        array of axes that are in step.  The arithmetic runs on all A columns, those not in
        ``cols`` not stored (why: module docstring, "Gaps").
        """
        c0 = 0 if isinstance(cols, slice) else cols[0]
        seg = int(st.seg[c0])
        if seg < 0:
            seg = 0
            st.n_segments[cols] += 1
            for li in range(len(self._levels)):
                st.hist[li][0, cols] = 0.0  # x_0 = 0: phase index 0 is a multiple of any stride
            for hist in st.shist:
                hist[:2, cols] = 0.0  # S_0 = S_1 = 0 (index 1 is stored at stride 1 only)
        r = samples.shape[0]
        phase = np.cumsum(samples - st.offset, axis=0)  # indices seg+1 .. seg+r
        # S indices seg+2 .. seg+r+1 (S_{n+1} = S_n + x_n; the newest S, index seg+1, is 0).
        cum = np.cumsum(phase, axis=0) if self._mdev else None
        slot = st.bucket % self._n_buckets
        windowed = self._bucket_len is not None
        for li, (s, f0, qs, cap) in enumerate(self._levels):
            h = min(seg // s + 1, cap)  # stored phase points of this level
            first = (seg // s + 1) * s
            if first <= seg + r:
                x = np.concatenate((st.hist[li][:h], phase[first - seg - 1:r:s]))
                self._book2(x, h, qs, f0, st.sums['oadev'], st.sums.get('ohdev'), cols, slot,
                            windowed)
                keep = min(x.shape[0], cap)
                st.hist[li][:keep, cols] = x[x.shape[0] - keep:, cols]
            if self._mdev:
                self._feed_s(st, li, seg, r, cum, phase[-1, cols], cols, slot, windowed)
        # Rebase: second differences ignore a constant, so shift every stored phase by the
        # newest one; the phase then never grows with run time (no loss of float precision).
        shift = phase[-1, cols]
        for li, (s, _, _, cap) in enumerate(self._levels):
            st.hist[li][:min((seg + r) // s + 1, cap), cols] -= shift
        st.seg[cols] = seg + r

    def _feed_s(self, st, li, seg, r, cum, shift, cols, slot, windowed):
        """
        MVAR terms of one level from the new S points ``cum`` (indices seg+2 .. seg+r+1).

        Then the level's S history is rebased: minus the newest S and the line of slope
        ``shift`` (the phase shift of this run) through it; a third difference ignores both,
        and this keeps S_{n+1} = S_n + x_n on the shifted phase (module docstring).
        """
        s, f0, qs, _ = self._levels[li]
        s_cap = self._s_caps[li]
        newest = seg + r + 1
        stored = min(newest // s + 1, s_cap)  # after this run
        # offsets of the stored points from the newest S index, oldest first
        lag = (newest // s * s - newest) - self._s_lags[li][s_cap - stored:]
        rebase = cum[-1, cols] + lag * shift
        h = min((seg + 1) // s + 1, s_cap)  # stored S points of this level
        first = ((seg + 1) // s + 1) * s
        if first > newest:  # no new point at this stride
            st.shist[li][:stored, cols] -= rebase
            return
        y = np.concatenate((st.shist[li][:h], cum[first - seg - 2:r:s]))
        self._book3(y, h, qs, f0, st.sums['mdev'], cols, slot, windowed)
        st.shist[li][:stored, cols] = y[y.shape[0] - stored:, cols] - rebase

    @staticmethod
    def _book2(x, h, qs, f0, sums2, sums3, cols, slot, windowed):
        """
        Add the new AVAR terms of one level's phase history ``x``, and OHVAR's unless None.

        ``x``: the level's history, its first ``h`` points stored before; lags q are the
        level's factors / stride; ``sums2``, ``sums3`` are [acc, cnt, wacc, wcnt] of the kinds.
        A third difference at lag q is the difference of two second differences q apart
        (D3_k = D2_{k+q} - D2_k), so the second differences are formed once, from the oldest
        new OHVAR term's k on.
        """
        length = x.shape[0]
        # Factors with new terms: 2 q < length, a prefix of the level's (q ascending).
        nv = bisect.bisect_right(qs, (length - 1) // 2)
        if not nv:
            return
        nv3 = 0 if sums3 is None else bisect.bisect_right(qs, (length - 1) // 3)
        ss = np.empty((nv, x.shape[1]))
        kk = np.empty((nv, 1), np.int64)
        ss3 = np.empty((nv3, x.shape[1]))
        kk3 = np.empty((nv3, 1), np.int64)
        for i in range(nv):
            q = qs[i]
            k0 = max(0, h - 2 * q)
            k1 = length - 2 * q
            e0 = max(0, h - 3 * q) if i < nv3 else k0
            d2 = x[e0 + 2 * q:k1 + 2 * q] - 2.0 * x[e0 + q:k1 + q] + x[e0:k1]
            d = d2[k0 - e0:]
            np.einsum('ij,ij->j', d, d, out=ss[i])
            kk[i] = k1 - k0
            if i < nv3:
                d = d2[q:] - d2[:d2.shape[0] - q]
                np.einsum('ij,ij->j', d, d, out=ss3[i])
                kk3[i] = d.shape[0]
        _add_terms(sums2, f0, cols, ss, kk, slot, windowed)
        if nv3:
            _add_terms(sums3, f0, cols, ss3, kk3, slot, windowed)

    @staticmethod
    def _book3(y, h, qs, f0, sums, cols, slot, windowed):
        """Add the new MVAR terms (third differences) of one level's S history (as _book2)."""
        length = y.shape[0]
        nv = bisect.bisect_right(qs, (length - 1) // 3)
        if not nv:
            return
        ss = np.empty((nv, y.shape[1]))
        kk = np.empty((nv, 1), np.int64)
        for i in range(nv):
            q = qs[i]
            k0 = max(0, h - 3 * q)
            k1 = length - 3 * q
            d = (y[k0 + 3 * q:k1 + 3 * q] - y[k0:k1]
                 - 3.0 * (y[k0 + 2 * q:k1 + 2 * q] - y[k0 + q:k1 + q]))
            np.einsum('ij,ij->j', d, d, out=ss[i])
            kk[i] = k1 - k0
        _add_terms(sums, f0, cols, ss, kk, slot, windowed)

    # -- output ------------------------------------------------------------------------------

    def _current_state(self):
        """Return the state with the unfinished frame (on a copy; the committed one is kept)."""
        if self._pend_n == 0:
            return self._st
        st = copy.deepcopy(self._st)
        n = self._pend_n
        self._process(st, self._pend[:n], self._pend_use[:n], self._pend_brk[:n],
                      self._pend_mixed)
        return st

    def sums(self, window=False, kind='oadev'):
        """
        Raw running sums: ``(m, stride, sum_sq (F, A), count (F, A))`` in sample units.

        ``sum_sq[f, a] / (2 m^2 count[f, a])`` is the Allan variance of axis ``a`` in the
        samples' unit squared (``kind`` ohdev: / (6 m^2 count), mdev: / (2 m^4 count)); the
        counts differ between axes when values were left out on some axes only.
        """
        return self._sums_of(self._current_state(), window, kind)

    def _sums_of(self, st, window, kind):
        if kind not in self.kinds:
            raise ValueError(f'{kind!r} is not computed (estimators: {", ".join(self.kinds)})')
        acc, cnt, wacc, wcnt = st.sums[kind]
        if window:
            if self._bucket_len is None:
                raise ValueError('no sliding window configured (window_s = 0)')
            return self.ms, self.strides, wacc.sum(axis=0), wcnt.sum(axis=0)
        return self.ms, self.strides, acc.copy(), cnt.copy()

    def snapshot(self, window=False, min_clusters=None, kind='oadev'):
        """
        Return the reportable factors now: ``(m, avar (T, A), n_eff (T, A))``, or None.

        A factor is reportable on an axis once that axis's terms span ``min_clusters`` x m
        samples; the factors reportable on at least one axis are returned, with NaN AVAR (and
        ``n_eff`` 0) on the axes where it is not.  ``n_eff`` is the span each factor's terms
        cover on each axis (count x stride + 2m - 1 samples; 3m - 1 for ohdev, 3m - 2 for
        mdev), used as the record length for the EDF.  AVAR (MVAR, OHVAR with ``kind``) in the
        samples' unit squared.
        """
        return self._snapshot_of(self._current_state(), window, min_clusters, kind)

    def snapshots(self, window=False, min_clusters=None):
        """Return :meth:`snapshot` of every computed kind, ``{kind: snapshot}``, of one state."""
        st = self._current_state()
        return {kind: self._snapshot_of(st, window, min_clusters, kind) for kind in self.kinds}

    def _snapshot_of(self, st, window, min_clusters, kind):
        ms, strides, acc, cnt = self._sums_of(st, window, kind)
        order, scale, power, lead = _SPEC[kind]
        min_clusters = self.min_clusters if min_clusters is None else int(min_clusters)
        n_eff = cnt * strides[:, None] + order * ms[:, None] + lead
        ok = (cnt > 0) & (n_eff >= min_clusters * ms[:, None])
        sel = ok.any(axis=1)
        if not sel.any():
            return None
        m, ok, cnt = ms[sel], ok[sel], cnt[sel]
        avar = np.full(ok.shape, np.nan)
        if kind == 'oadev':  # as before the other kinds (bit-identical)
            avar[ok] = acc[sel][ok] / (2.0 * (m[:, None] * m[:, None] * cnt)[ok].astype(float))
        else:  # in floats: m^4 overflows int64 from m = 55109
            mf = m[:, None].astype(float)
            avar[ok] = acc[sel][ok] / (scale * mf ** power * cnt)[ok]
        return m, avar, np.where(ok, n_eff[sel], 0)

    def result_from(self, snapshot, columns=None):
        """Build an AllanResult (EDF, intervals) of a :meth:`snapshot`, optionally some columns."""
        if snapshot is None:
            return None
        m, avar, n_eff = snapshot
        columns = range(len(self.axes)) if columns is None else columns
        columns = list(columns)
        return AllanResult.from_avar(m, avar[:, columns], n_eff[:, columns], self.rate_hz,
                                     [self.axes[j] for j in columns])

    def deviation_from(self, kind, snapshot):
        """Return a :class:`StreamingDeviation` of a :meth:`snapshot` of ``kind`` (or None)."""
        if snapshot is None:
            return None
        m, var, n_eff = snapshot
        return StreamingDeviation(kind, m / self.rate_hz, m, np.sqrt(var), n_eff, self.axes,
                                  self.rate_hz)

    def deviation(self, kind, window=False, min_clusters=None):
        """
        Return the deviation ``kind`` (oadev, mdev, ohdev) of all data seen, or of the window.

        A :class:`StreamingDeviation` (values, no intervals), or None before enough data.
        """
        return self.deviation_from(kind, self.snapshot(window, min_clusters, kind))

    def result(self, window=False, min_clusters=None):
        """
        Allan deviation of everything seen (or of the sliding window) as an AllanResult.

        None when no factor has enough data yet (see :meth:`snapshot`); NaN on an axis at
        the averaging times that axis has too little data for.
        """
        return self.result_from(self.snapshot(window, min_clusters))


@dataclass(frozen=True)
class StreamingDeviation:
    """
    One streaming deviation curve: ``kind``, ``tau`` (T,) s, ``m`` (T,), ``dev`` (T, A).

    ``dev`` in the samples' unit (rad/s, m/s^2), NaN on an axis at the averaging times its own
    data do not reach; ``n_eff`` (T, A) samples spanned by each factor's terms.
    """

    kind: str
    tau: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    n_eff: np.ndarray
    axes: tuple
    rate_hz: float

    def axis_index(self, axis):
        """Column of ``axis`` in ``dev``."""
        return self.axes.index(axis)


def _add_terms(sums, f0, cols, sq, counts, slot, windowed):
    """
    Add one level's new terms into a kind's running sums ``[acc, cnt, wacc, wcnt]``.

    ``sq`` (F', A): the sums of squared differences of the factors f0 .. f0 + F' - 1 on every
    column (only ``cols`` are stored), ``counts`` (F', 1) their numbers of terms; with
    ``windowed`` also into the window bucket ``slot``.
    """
    fs = slice(f0, f0 + sq.shape[0])
    sq = sq[:, cols]
    acc, cnt, wacc, wcnt = sums
    acc[fs, cols] += sq
    cnt[fs, cols] += counts
    if windowed:
        wacc[slot][fs, cols] += sq
        wcnt[slot][fs, cols] += counts


def _as_mask(mask, n, n_axes, name):
    """Return a bool mask as (n, 1) (whole samples) or (n, A) (per axis)."""
    mask = np.asarray(mask, bool)
    if mask.ndim == 1:
        mask = mask[:, None]
    if mask.shape[0] != n or mask.shape[1] not in (1, n_axes):
        raise ValueError(f'{name} must have shape ({n},) or ({n}, {n_axes}), '
                         f'got {mask.shape}')
    return mask
