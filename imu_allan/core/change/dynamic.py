"""
Dynamic Allan deviation: the overlapping Allan variance over sliding windows.

Galleani & Tavella, "The dynamic Allan variance", IEEE TUFFC 56(3), 2009: sigma^2(t, tau) is
the Allan variance of the window of length W centred on t.  Galleani, "The dynamic Allan
variance II: a fast computational algorithm", IEEE TUFFC 57(1), 2010: consecutive windows
share all but a few terms, so each window's sum is a running (cumulative) sum updated by the
terms that enter and leave, and missing data are handled by counting only the terms whose
samples are all present.

Here every window is a run of ``k`` consecutive *blocks* of ``step`` samples (W = k step),
and :class:`BlockAllan` accumulates, per block, averaging factor m and axis, the sum of the
squared second differences of the phase (NIST SP1065 eq. 11 without its normalisation) and
their number.  A window's AVAR at m is then ``sum / (2 m^2 count)`` over its blocks (phase in
units of summed samples: AVAR = <(S_{k+2m} - 2 S_{k+m} + S_k)^2> / (2 m^2), S the cumulative
sum of the rate samples), so all windows of one m come from one cumulative sum over blocks.
A term belongs to the block holding its *last* sample (the stream form can emit a block as
soon as it is complete), so a window's terms at factor m may start up to 2m - 1 samples
before it.

Long averaging factors are computed on a pyramid of pairwise block sums (level L sums 2^L
samples): factor m = m' 2^L with m' in (8, 12) uses the terms at a stride of 2^L samples
(8 or 12 overlapping positions per m instead of m; the EDF is within a few percent of the
fully overlapping one).  The averaging factors are the half-octave grid 1, 2, 3, 4, 6, 8, 12,
16, 24, ...  The same code runs on a whole record (``analyze --dynamic``) and on a live stream
in batches (the allan node): it keeps only the pyramid's last 2 x 12 + 1 partial sums per
level and the open block, not samples.

A sample that is NaN is missing: every term that spans it is left out (its own axis only).

Units: rate samples in SI (rad/s, m/s^2); AVAR in (unit)^2; times in s from the first sample.
"""

from dataclasses import dataclass

import numpy as np

#: Averaging factors m' used at pyramid levels >= 1 (m = m' 2^L): half-octave steps.
LEVEL_FACTORS = (8, 12)
#: Factors computed on the full-rate series (level 0).
BASE_FACTORS = (1, 2, 3, 4, 6, 8, 12)
#: Fewest terms-per-window ratio: the longest tau of a window is W / MIN_CLUSTERS.
MIN_CLUSTERS = 10
#: Default window: the record length / WINDOWS_PER_RECORD, clipped to these bounds (s) and at
#: least MIN_WINDOW_SAMPLES samples; step = window / BLOCKS_PER_WINDOW.
WINDOWS_PER_RECORD = 24
WINDOW_MIN_S, WINDOW_MAX_S = 60.0, 3600.0
MIN_WINDOW_SAMPLES = 2000
BLOCKS_PER_WINDOW = 4


def default_window(duration_s, rate_hz):
    """
    Return the default window length (s): ``duration / 24`` clipped to [60 s, 1 h].

    At least 2000 samples.  A day's record gets 1 h windows (long enough for the flat
    bias-instability region of the usual MEMS models at tau up to 6 min); a 1-h record 2.5-min
    windows.
    """
    window = min(max(duration_s / WINDOWS_PER_RECORD, WINDOW_MIN_S), WINDOW_MAX_S)
    return max(window, MIN_WINDOW_SAMPLES / rate_hz)


def factor_grid(m_max):
    """Half-octave averaging factors up to ``m_max``: 1, 2, 3, 4, 6, 8, 12, 16, 24, ..."""
    ms = [m for m in BASE_FACTORS if m <= m_max]
    level = 1
    while LEVEL_FACTORS[0] << level <= m_max:
        ms += [f << level for f in LEVEL_FACTORS if f << level <= m_max]
        level += 1
    return np.array(ms, dtype=np.int64)


def layout(window_s, rate_hz, k=BLOCKS_PER_WINDOW):
    """
    Return ``(block_samples, ms)`` for a window of ``window_s`` s: blocks of W / k samples.

    The block length is rounded to a multiple of the coarsest pyramid level's span (at most
    5 % off: that span is at most the longest factor / 8 <= W / 80), so that a block is
    complete at every level when its last sample arrives.
    """
    window_n = int(round(window_s * rate_hz))
    ms = factor_grid(max(window_n // MIN_CLUSTERS, 1))
    span = 1 << _level_of(int(ms[-1]))
    block = max(int(round(window_n / k / span)), 1) * span
    return block, ms


def _level_of(m):
    """Pyramid level of factor ``m`` (0 for the base factors)."""
    if m in BASE_FACTORS:
        return 0
    level = 0
    while (m >> level) not in LEVEL_FACTORS or (m >> level) << level != m:
        level += 1
    return level


class _Level:
    """One pyramid level: the cumulative sums' tail and the factors computed on it."""

    def __init__(self, level, factors, n_axes):
        self.level = level
        self.factors = factors  # m' on this level
        self.keep = 2 * max(factors) + 1 if factors else 1
        self.s_tail = np.zeros((1, n_axes))  # cumulative sums S_p, p = first .. first + len - 1
        self.b_tail = np.zeros((1, n_axes))  # cumulative count of missing values
        self.first = 0  # absolute level position of s_tail[0]
        self.carry = None  # an unpaired value waiting for the next level


class BlockAllan:
    """
    Per-block sums of squared second differences at every averaging factor (stream form).

    ``block_samples``: a multiple of 2^level of the coarsest factor of ``ms`` (from
    :func:`factor_grid`; :func:`layout` gives both).  :meth:`feed` takes samples ``(n, A)`` in
    any batch sizes and returns the blocks completed by them: a :class:`Blocks`.  Memory is
    fixed: per level 25 partial sums per axis, and one open block's sums.
    """

    def __init__(self, n_axes, block_samples, ms):
        self.n_axes = n_axes
        self.block = int(block_samples)
        self.ms = np.asarray(ms, dtype=np.int64)
        self.levels = []
        top = max(_level_of(int(m)) for m in self.ms)
        for level in range(top + 1):
            factors = [int(m) >> level for m in self.ms if _level_of(int(m)) == level]
            self.levels.append(_Level(level, factors, n_axes))
        if self.block % (1 << top):
            raise ValueError('block_samples must be a multiple of the coarsest level span')
        self._col = {int(m): i for i, m in enumerate(self.ms)}
        self.n_fed = 0
        self.offset = None  # first finite value per axis, subtracted (precision of the sums)
        self._open = self._empty(1)

    def _empty(self, n):
        a, nm = self.n_axes, self.ms.size
        return Blocks(np.zeros((n, nm, a)), np.zeros((n, nm, a)), np.zeros((n, a)),
                      np.zeros((n, a)), 0)

    def memory_bytes(self):
        """Bytes held (fixed)."""
        held = sum(lv.s_tail.nbytes + lv.b_tail.nbytes for lv in self.levels)
        return held + sum(v.nbytes for v in self._open.arrays())

    def feed(self, data):
        """Add samples ``(n, A)`` (NaN = missing); return the :class:`Blocks` they complete."""
        data = np.asarray(data, dtype=float)
        if data.ndim == 1:
            data = data[:, None]
        n = data.shape[0]
        if self.offset is None or not np.all(np.isfinite(self.offset)):
            first = _first_finite(data)
            self.offset = first if self.offset is None else np.where(
                np.isfinite(self.offset), self.offset, first)
        b0 = self.n_fed // self.block  # the open block
        end = self.n_fed + n
        b1 = (end - 1) // self.block if n else b0
        out = self._empty(b1 - b0 + 1)
        for name, part in zip(('sums', 'counts', 'ysum', 'ycount'), self._open.arrays()):
            getattr(out, name)[:1] += part
        x = data - np.where(np.isfinite(self.offset), self.offset, 0.0)
        self._samples_into(out, x, b0)
        z = x
        for lv in self.levels:
            if z is None or z.shape[0] == 0:
                break
            self._terms_into(out, lv, z, b0)
            z = self._pair(lv, z)
        self.n_fed = end
        closed = end // self.block - b0
        done = out.take(slice(0, closed), b0)
        self._open = out.take(slice(closed, closed + 1), b0 + closed)
        if self._open.sums.shape[0] == 0:
            self._open = self._empty(1)
        return done

    def _samples_into(self, out, x, b0):
        """Block sums and counts of the samples themselves (for the level test)."""
        ok = np.isfinite(x)
        ids = (self.n_fed + np.arange(x.shape[0])) // self.block - b0
        nb = out.ysum.shape[0]
        out.ysum += _block_sum(ids, np.where(ok, x, 0.0), nb)
        out.ycount += _block_sum(ids, ok.astype(float), nb)

    def _terms_into(self, out, lv, z, b0):
        """Second differences of this level's new values, summed into their blocks."""
        bad = ~np.isfinite(z)
        s_new = lv.s_tail[-1] + np.cumsum(np.where(bad, 0.0, z), axis=0)
        b_new = lv.b_tail[-1] + np.cumsum(bad, axis=0)
        s = np.concatenate((lv.s_tail, s_new))
        b = np.concatenate((lv.b_tail, b_new))
        n_old = lv.s_tail.shape[0]
        first = lv.first
        nb = out.ysum.shape[0]
        for f in lv.factors:
            lo = max(n_old, 2 * f - first)  # end positions (array index) with a full term
            if lo >= s.shape[0]:
                continue
            hi = s.shape[0]
            d = s[lo:] - 2.0 * s[lo - f:hi - f] + s[lo - 2 * f:hi - 2 * f]
            ok = b[lo:] == b[lo - 2 * f:hi - 2 * f]
            ends = (first + np.arange(lo, hi)) << lv.level  # exclusive end, in samples
            ids = (ends - 1) // self.block - b0
            col = self._col[f << lv.level]
            d *= d
            d[~ok] = 0.0
            out.sums[:, col] += _block_sum(ids, d, nb)
            out.counts[:, col] += _block_sum(ids, ok.astype(float), nb)
        cut = max(s.shape[0] - lv.keep, 0)
        lv.s_tail, lv.b_tail = s[cut:], b[cut:]
        lv.first = first + cut

    @staticmethod
    def _pair(lv, z):
        """Return the next level's values: sums of consecutive pairs (an odd one waits)."""
        if lv.carry is not None:
            z = np.concatenate((lv.carry, z))
        n2 = z.shape[0] // 2 * 2
        lv.carry = z[n2:] if n2 < z.shape[0] else None
        return z[0:n2:2] + z[1:n2:2]  # NaN stays NaN: the pair is missing


def _block_sum(ids, values, nb):
    """Return the sums of the rows of ``values`` per sorted block id 0 .. nb-1: (nb, A)."""
    if nb == 1:  # the stream's usual batch: inside one block
        return values.sum(axis=0, keepdims=True)
    starts = np.searchsorted(ids, np.arange(nb))
    out = np.zeros((nb, values.shape[1]))
    full = starts < ids.size
    if not full.any():
        return out
    sums = np.add.reduceat(values, starts[full], axis=0)
    empty = np.append(starts[full][1:] == starts[full][:-1], False)  # reduceat's empty runs
    sums[empty] = 0.0
    out[full] = sums
    return out


def _first_finite(data):
    good = np.isfinite(data)
    first = data[np.argmax(good, axis=0), np.arange(data.shape[1])] if data.shape[0] else np.nan
    return np.where(good.any(axis=0), first, np.nan)


@dataclass
class Blocks:
    """
    Completed blocks of :class:`BlockAllan`.

    ``sums``/``counts`` (nb, M, A) of squared second differences (in
    summed-sample units) and their number; ``ysum``/``ycount`` (nb, A) the sum and number of
    the samples (offset removed); ``first`` the index of the first block.
    """

    sums: np.ndarray
    counts: np.ndarray
    ysum: np.ndarray
    ycount: np.ndarray
    first: int

    def arrays(self):
        """Return the four arrays, in field order."""
        return self.sums, self.counts, self.ysum, self.ycount

    def take(self, rows, first):
        """Return the blocks ``rows`` (a slice) as a new :class:`Blocks` starting at ``first``."""
        return Blocks(*(v[rows] for v in self.arrays()), first)

    @property
    def n(self):
        """Return the number of blocks."""
        return self.sums.shape[0]


@dataclass
class DynamicResult:
    """
    Dynamic Allan deviation of a record.

    ``t`` (nw,) window centres, s from the first sample; ``tau`` (M,) s; ``avar``/``adev``
    (nw, M, A), NaN where a window has no term; ``window_s``, ``step_s`` (the block length);
    ``blocks`` the per-block sums (for the change test); ``ms`` the averaging factors.
    """

    t: np.ndarray
    tau: np.ndarray
    ms: np.ndarray
    avar: np.ndarray
    counts: np.ndarray
    window_s: float
    step_s: float
    rate_hz: float
    axes: tuple
    blocks: Blocks

    @property
    def adev(self):
        """Allan deviation (nw, M, A), unit of the samples."""
        return np.sqrt(self.avar)

    @property
    def k(self):
        """Blocks per window."""
        return int(round(self.window_s / self.step_s))


def window_avar(blocks, ms, k):
    """
    AVAR over every run of ``k`` consecutive blocks: ``(avar (nw, M, A), counts)``.

    One cumulative sum over blocks per array (Galleani 2010's recursive update).
    """
    nw = blocks.n - k + 1
    if nw < 1:
        shape = (0,) + blocks.sums.shape[1:]
        return np.zeros(shape), np.zeros(shape)
    zero = np.zeros((1,) + blocks.sums.shape[1:])
    cs = np.concatenate((zero, np.cumsum(blocks.sums, axis=0)))
    cc = np.concatenate((zero, np.cumsum(blocks.counts, axis=0)))
    sums, counts = cs[k:] - cs[:-k], cc[k:] - cc[:-k]
    m = np.asarray(ms, dtype=float)[None, :, None]
    with np.errstate(invalid='ignore', divide='ignore'):
        avar = np.where(counts > 0, sums / (2.0 * m * m * counts), np.nan)
    return avar, counts


def dynamic_allan(data, rate_hz, window_s=None, axes=None, k=BLOCKS_PER_WINDOW):
    """
    Dynamic Allan variance of a record ``data`` (n, A) sampled at ``rate_hz`` (Hz).

    ``window_s`` default: :func:`default_window`.  The step is window / ``k`` (rounded to the
    block length of :func:`layout`); averaging times tau0 .. W / 10 on the half-octave grid.
    Raises ValueError when the record is shorter than two windows.
    """
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    n = data.shape[0]
    if window_s is None:
        window_s = default_window(n / rate_hz, rate_hz)
    block, ms = layout(window_s, rate_hz, k)
    if n < 2 * k * block:
        raise ValueError(f'record of {n / rate_hz:.4g} s is shorter than two windows of '
                         f'{k * block / rate_hz:.4g} s')
    if k * block < 2 * MIN_CLUSTERS:
        raise ValueError(f'window of {window_s:g} s holds fewer than {2 * MIN_CLUSTERS} '
                         'samples')
    acc = BlockAllan(data.shape[1], block, ms)
    blocks = acc.feed(data)
    avar, counts = window_avar(blocks, ms, k)
    step_s = block / rate_hz
    t = (np.arange(avar.shape[0]) * block + k * block / 2.0) / rate_hz
    return DynamicResult(t, ms / rate_hz, ms, avar, counts, k * step_s, step_s, float(rate_hz),
                         tuple(axes) if axes is not None else tuple(
                             f'axis{j}' for j in range(data.shape[1])), blocks)


def normalized_adev(result):
    """
    ADEV divided by the whole record's ADEV at each tau and axis (the colour map's values).

    The record's value is the median over windows (robust to a change in part of it).
    """
    with np.errstate(invalid='ignore'):
        ref = np.nanmedian(result.adev, axis=0, keepdims=True)
        return result.adev / ref


def phase_count(count, m):
    """Fully overlapping terms a strided count stands for (EDF input): count x stride."""
    level = _level_of(int(m))
    return count * (1 << level) + 2 * int(m)


__all__ = ['BlockAllan', 'Blocks', 'default_window', 'dynamic_allan', 'DynamicResult',
           'factor_grid', 'layout', 'normalized_adev', 'window_avar']
