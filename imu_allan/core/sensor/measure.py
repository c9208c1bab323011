"""
The sensor's own processing, measured from its samples: LSB grid, repeats, filter, lines, humps.

A real IMU rounds each sample to an LSB, filters at an internal rate before decimating, may
hold a sample, and carries lines and broad resonances.  :func:`measure_sensor` reads that from a
record ``(n, A)`` in SI units, :class:`SensorAccumulator` from blocks as they arrive.  Per axis
(:class:`AxisSensor`; docs/method.md section 9 gives the rules and the derivation):

* **Grid** (``resolution``, the LSB): the smallest step of the first :data:`GRID_SAMPLES`
  values, refined; coarser than :data:`GRID_MIN_RELATIVE` of the largest magnitude, else it is
  float storage.  **Repeats**: consecutive samples exactly equal.
* **Quantization regime**: ``'fine'`` when the noise before rounding has std
  sigma = sqrt(R_0 - q^2 / 12) >= q / 2 (Widrow's quantization theorem: the rounding error is
  then uniform and uncorrelated to 1 %), adding white noise of density q / sqrt(12 fs); else
  ``'coarse'``.
* **The white part** (the filter): autocovariance R_0..R_K fitted as the coefficients of its
  spectrum (:func:`.spectrum.fit_white`); S = R_0 + 2 sum R_k, D = 2 sum k R_k,
  ``bandwidth_hz`` = (R_0 / S) fs / 2, ``filter_moment`` = D / S samples, and for m >= K its
  Allan variance is S tau0 / tau - 1.5 D tau0^2 / tau^2 (:meth:`AxisSensor.white_avar`).
* **Lines** and **humps**: :mod:`.spectrum`.

Cost: at most :data:`MAX_EXAMINED` (2^18) samples per axis, about 0.05 s of CPU for 6 axes: a
longer record contributes MAX_EXAMINED / L non-overlapping Welch segments of L samples spread
evenly over it, a shorter one all its segments at 50 % overlap.  L is :data:`SEGMENT_SECONDS`
of samples rounded up to a power of two (8192 at 100 Hz), between 256 and 2^15, and at most a
quarter of a short record (not below 64).
"""

import dataclasses
from dataclasses import dataclass, field
import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .spectrum import find_lines, FIT_LOW_FRACTION, fit_white, Welch
from ..fit.tau_range import Processing
from ..units import AXES, sample_unit

#: Most samples per axis :func:`measure_sensor` examines (spread over a longer record).
MAX_EXAMINED = 2 ** 18
#: Welch segment length: this many seconds rounded up to a power of two, within the bounds.
SEGMENT_SECONDS = 64.0
MIN_SEGMENT, MAX_SEGMENT = 64, 2 ** 15
#: Samples (the first ones examined) in which the grid's step is looked for.
GRID_SAMPLES = 2 ** 14
#: A grid finer than this fraction of the largest magnitude is float storage, not an LSB.
GRID_MIN_RELATIVE = 2.0 ** -18
#: A value is on the grid within this fraction of the step; so many values may be off it.
GRID_TOL, MAX_OFF_GRID = 1e-3, 1e-3
#: Most distinct grid levels counted (beyond, the count stops: ``distinct_values`` None).
MAX_LEVELS = 2 ** 20
#: Fine quantization: noise std before rounding at least this many LSB (module docstring).
FINE_NOISE_LSB = 0.5
#: Lags reported in ``lag_correlation``.
REPORTED_LAGS = 8
_CHUNK = 2 ** 16


@dataclass
class AxisSensor:
    """
    What the samples of one axis say about the sensor's processing (SI; None: not measured).

    The quantities are those of the module docstring, their units :data:`JSON_UNITS`;
    ``unit`` is the SI unit of the samples (``rad/s`` or ``m/s^2``), ``rate_hz`` their rate
    (Hz), ``n_examined`` the finite samples examined, ``segment_length`` and ``segments`` the
    Welch segment length L (samples) and the segments averaged (0: no spectrum).
    ``distinct_values`` counts the distinct values among ``distinct_counted_over`` samples
    (all examined ones on a grid, else the first :data:`GRID_SAMPLES`); ``off_grid_fraction``
    is at most 1e-3 when ``resolution`` is set; ``quantization`` is None without a grid and
    ``quantization_density`` is set in the fine regime only; ``filter_length`` is 0 for
    uncorrelated samples (``bandwidth_hz`` then fs / 2).
    """

    axis: str
    unit: str
    rate_hz: float
    n_examined: int = 0
    segment_length: int = 0
    segments: int = 0
    resolution: float = None
    distinct_values: int = None
    distinct_counted_over: int = 0
    repeated_fraction: float = None
    off_grid_fraction: float = None
    quantization: str = None
    quantization_density: float = None
    noise_to_lsb: float = None
    lag_correlation: tuple = None
    lag_correlation_se: tuple = None
    filter_length: int = None
    bandwidth_hz: float = None
    filter_moment: float = None
    white_autocovariance: tuple = None
    white_variance: float = None
    lines: list = field(default_factory=list)
    humps: list = field(default_factory=list)

    @property
    def white_density(self):
        """Continuous-time density of the white part at low frequency, sqrt(S / fs), SI."""
        if self.white_variance is None or not self.white_variance > 0:
            return None
        return math.sqrt(self.white_variance / self.rate_hz)

    def white_avar(self, tau):
        """
        Allan variance of the white part at averaging times ``tau`` (s), SI^2; None unmeasured.

        S tau0 / tau - 1.5 D tau0^2 / tau^2: exact for m = tau / tau0 >= ``filter_length``.
        """
        if self.white_autocovariance is None:
            return None
        s, d = filter_sums(self.white_autocovariance)
        m = np.asarray(tau, dtype=float) * self.rate_hz
        return s / m - 1.5 * d / (m * m)

    def processing(self):
        """
        Return this axis as the fit takes it (:class:`~.fit.tau_range.Processing`).

        A "hump" that starts where the white part's fit starts (fs / 100) is a low-pass
        shape, not a resonance: the main lobe of a filter longer than the lags fitted (a
        32-tap window decimated by 5 reads as one lag and a 2-25 Hz hump).  The fit takes it
        as the filter: correlated over about fs / f_hi samples (the lobe's width), its deficit
        fitted (:mod:`..fit.tau_range`), no cut.
        """
        length, moment = self.filter_length or 0, self.filter_moment or 0.0
        humps = []
        for h in self.humps:
            lo, hi = h.frequency_range_hz
            if lo <= 2.0 * self.rate_hz / FIT_LOW_FRACTION:
                length = max(length, math.ceil(self.rate_hz / hi))
                moment = max(moment, 1.0)  # its size is the fit's; this says there is one
            else:
                humps.append((lo, hi, h.excess_variance))
        return Processing(length, moment,
                          tuple((ln.frequency_hz, ln.amplitude) for ln in self.lines),
                          tuple(humps))

    def to_json(self):
        """Return a JSON-ready dict: SI, per sample or continuous time as :data:`JSON_UNITS`."""
        return {
            'unit': self.unit, 'n_examined': self.n_examined,
            'segment_length': self.segment_length, 'segments': self.segments,
            'resolution': _num(self.resolution), 'distinct_values': self.distinct_values,
            'distinct_counted_over': self.distinct_counted_over,
            'repeated_fraction': _num(self.repeated_fraction),
            'off_grid_fraction': _num(self.off_grid_fraction),
            'quantization': self.quantization,
            'quantization_density': _num(self.quantization_density),
            'noise_to_lsb': _num(self.noise_to_lsb),
            'lag_correlation': _nums(self.lag_correlation),
            'lag_correlation_se': _nums(self.lag_correlation_se),
            'filter_length': self.filter_length, 'bandwidth_hz': _num(self.bandwidth_hz),
            'filter_moment': _num(self.filter_moment),
            'white_autocovariance': _nums(self.white_autocovariance),
            'white_variance': _num(self.white_variance),
            'white_density': _num(self.white_density),
            'lines': [line.to_json() for line in self.lines],
            'humps': [hump.to_json() for hump in self.humps],
        }


#: What the numbers of :meth:`SensorReport.to_json` are ("sample unit": the axis's ``unit``).
JSON_UNITS = {
    'resolution': 'sample unit (one LSB)',
    'quantization_density': 'sample unit/sqrt(Hz), continuous time',
    'noise_to_lsb': 'LSB',
    'lag_correlation': 'correlation coefficient at lags 1..8 samples',
    'filter_length': 'samples', 'filter_moment': 'samples', 'bandwidth_hz': 'Hz',
    'white_autocovariance': 'sample unit^2, per sample, lags 0..filter_length',
    'white_variance': 'sample unit^2, per sample (S = R_0 + 2 sum R_k)',
    'white_density': 'sample unit/sqrt(Hz), continuous time (sqrt(S / fs))',
    'lines.frequency_hz': 'Hz, as sampled (alias)',
    'lines.amplitude': 'sample unit, peak (root mean square over the record)',
    'lines.snr': 'line power / noise power in one Welch bin',
    'humps.excess_variance': 'sample unit^2, per sample',
}


@dataclass
class SensorReport:
    """Per-axis :class:`AxisSensor` (``axes``: name -> AxisSensor) of a record."""

    rate_hz: float
    n_samples: int
    axes: dict

    def processing(self, filter_window_s=None):
        """
        ``{axis: Processing}``: what the fit needs of each axis (:mod:`.fit.tau_range`).

        The filter's length and moment (a negative moment, white phase noise's, is left to
        the quantization term), the lines as (frequency, amplitude), the humps as
        (f_lo, f_hi, excess variance).  ``filter_window_s``: the device's moving-average
        window, s, when known: its filter (:meth:`.Processing.moving_average`) replaces the
        measured one (a float-output device, where nothing else correlates the samples).
        """
        out = {}
        device = (Processing.moving_average(filter_window_s * self.rate_hz) if filter_window_s
                  else None)
        for name, ax in self.axes.items():
            proc = ax.processing()
            if device is not None:
                proc = dataclasses.replace(proc, filter_length=device.filter_length,
                                           filter_moment=device.filter_moment,
                                           filter_known=True)
            out[name] = proc
        return out

    def to_json(self):
        """Return the ``sensor`` entry of report.json (SI; None for what was not measured)."""
        return {'rate_hz': self.rate_hz, 'n_samples': self.n_samples,
                'max_examined_per_axis': MAX_EXAMINED, 'units': dict(JSON_UNITS),
                'axes': {name: ax.to_json() for name, ax in self.axes.items()}}


def filter_sums(autocovariance):
    """
    Return S = R_0 + 2 sum R_k and D = 2 sum k R_k of the white part's R_0..R_K.

    S is the per-sample variance of white samples with the same low-frequency density, D the
    first moment that sets the 1/tau^2 part of the Allan variance (docs/method.md section 9).
    """
    r = np.asarray(autocovariance, dtype=float)
    return float(r[0] + 2.0 * r[1:].sum()), float(2.0 * (np.arange(r.size) * r).sum())


def _num(value):
    return None if value is None or not math.isfinite(value) else float(value)


def _nums(values):
    return None if values is None else [_num(v) for v in values]


def segment_length(rate_hz, n_samples=None):
    """Welch segment length (samples) at ``rate_hz`` (Hz) for a record of ``n_samples``."""
    wanted = max(SEGMENT_SECONDS * rate_hz, 1.0)
    length = min(max(2 ** math.ceil(math.log2(wanted)), 256), MAX_SEGMENT)
    if n_samples is not None:
        while length > MIN_SEGMENT and 4 * length > n_samples:
            length //= 2
    return length


def measure_sensor(data, rate_hz, axes=None):
    """
    Measure the sensor's processing from a record; return a :class:`SensorReport`.

    ``data`` (n, A) in SI units (rad/s, m/s^2; a 1-D array is one axis), ``rate_hz`` the
    sample rate, ``axes`` the axis names (default ``gyro_x, ...`` in order).  At most
    :data:`MAX_EXAMINED` samples per axis are examined: all of a shorter record (Welch
    segments at 50 % overlap), else non-overlapping segments spread evenly over it.
    Non-finite samples are left out (a segment holding one is skipped).  Degenerate input
    (short, constant, one axis) gives a report with what could be measured, never an error;
    a rate that is not a positive number raises ValueError.
    """
    _check_rate(rate_hz)
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    axes = _axis_names(axes, data.shape[1])
    n = data.shape[0]
    length = segment_length(rate_hz, n)
    whole = n <= MAX_EXAMINED
    if whole:
        examined, spacing = data, length // 2
    else:   # non-overlapping segments spread over the record: the examined samples, in order
        starts = np.rint(np.linspace(0, n - length, MAX_EXAMINED // length)).astype(np.int64)
        examined, spacing = np.concatenate([data[s:s + length] for s in starts]), length
    out = {}
    for a, name in enumerate(axes):
        x = np.ascontiguousarray(examined[:, a])    # one strided pass, then contiguous ones
        stats = _ValueStats()
        stats.add_head(x[:GRID_SAMPLES])
        stats.update(x, segment=None if whole else length)
        welch = Welch(length)
        if n >= 4 * MIN_SEGMENT:
            welch.add(sliding_window_view(x, length)[::length // 2] if whole
                      else x.reshape(-1, length))
        out[name] = _axis_report(name, rate_hz, stats, welch, spacing)
    return SensorReport(float(rate_hz), int(n), out)


def _check_rate(rate_hz):
    if not (isinstance(rate_hz, (int, float, np.floating, np.integer))
            and math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f'sample rate must be a positive number of Hz, not {rate_hz!r}')


def _axis_names(axes, count):
    if axes is None:
        return AXES[:count] if count <= len(AXES) else tuple(f'axis_{i}' for i in range(count))
    axes = tuple(axes)
    if len(axes) != count:
        raise ValueError(f'{len(axes)} axis names for {count} columns')
    return axes


class SensorAccumulator:
    """
    :func:`measure_sensor` from blocks of samples as they arrive, with bounded memory.

    ``update(block)`` takes rows (k, A) in SI units; ``report()`` returns a
    :class:`SensorReport`.  Until 4 L samples have arrived (L = :func:`segment_length` at the
    rate) they are kept and ``report()`` is :func:`measure_sensor` of them; then only the last
    L / 2 samples per axis, the running sums of the Welch periodograms (50 % overlap, every
    segment), the grid levels seen and the repeat counts are kept.  For a record of up to
    :data:`MAX_EXAMINED` samples the result is :func:`measure_sensor`'s (same segments, same
    values, only the order of the sums differs); a longer one is examined in full here.
    """

    def __init__(self, rate_hz, axes):
        """Start empty for ``axes`` (names) at ``rate_hz`` (Hz)."""
        _check_rate(rate_hz)
        self.rate_hz = float(rate_hz)
        self.axes = tuple(axes)
        self.length = segment_length(self.rate_hz)
        self.n = 0
        self._head = []          # blocks until 4 L samples have arrived
        self._tail = None        # samples after the last full segment's first half
        self._stats = self._welch = None

    def update(self, block):
        """Add rows ``block`` (k, A), SI units (a 1-D block is one row)."""
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[None, :]
        if block.shape[1] != len(self.axes):
            raise ValueError(f'block has {block.shape[1]} columns for {len(self.axes)} axes')
        if block.shape[0] == 0:
            return
        self.n += block.shape[0]
        if self._stats is None:
            self._head.append(block.copy())
            if self.n >= 4 * self.length:
                self._start(np.concatenate(self._head))
                self._head = []
            return
        for a, stats in enumerate(self._stats):
            stats.update(block[:, a])
        self._feed(block)

    def _start(self, head):
        self._stats = []
        for a in range(len(self.axes)):
            stats = _ValueStats()
            stats.add_head(head[:GRID_SAMPLES, a])
            stats.update(head[:, a])
            self._stats.append(stats)
        self._welch = [Welch(self.length) for _ in self.axes]
        self._tail = head[:0]
        self._feed(head)

    def _feed(self, block):
        """Add every complete segment (50 % overlap) of tail + block to the sums."""
        buf = np.concatenate([self._tail, block]) if self._tail.size else block
        hop = self.length // 2
        count = (buf.shape[0] - self.length) // hop + 1 if buf.shape[0] >= self.length else 0
        for a, welch in enumerate(self._welch):
            if count:
                col = np.ascontiguousarray(buf[:(count - 1) * hop + self.length, a])
                welch.add(sliding_window_view(col, self.length)[::hop])
        self._tail = buf[count * hop:].copy()

    def report(self):
        """Return the :class:`SensorReport` of everything added so far."""
        if self._stats is None:
            head = (np.concatenate(self._head) if self._head
                    else np.zeros((0, len(self.axes))))
            return measure_sensor(head, self.rate_hz, self.axes)
        out = {name: _axis_report(name, self.rate_hz, self._stats[a], self._welch[a],
                                  self.length // 2)
               for a, name in enumerate(self.axes)}
        return SensorReport(self.rate_hz, int(self.n), out)


class _ValueStats:
    """Grid, distinct levels and repeats of one axis, from values as they arrive."""

    def __init__(self):
        self.grid = None             # (origin, step) found in the head
        self.head_distinct = self.head_count = 0
        self.count = 0               # finite values seen
        self.pairs = self.repeats = 0
        self.off_grid = 0
        self.levels = np.zeros(0, dtype=np.int64)
        self.last = np.nan
        self.lo, self.hi = math.inf, -math.inf

    def add_head(self, head):
        """Look for the grid in the first values."""
        head = head[np.isfinite(head)]
        self.head_count = int(head.size)
        if head.size:
            u = np.unique(head)
            self.head_distinct = int(u.size)
            self.grid = _find_grid(u)

    def update(self, x, segment=None):
        """Count consecutive values ``x`` (``segment``: pairs across its multiples are not)."""
        if x.size == 0:
            return
        finite = np.isfinite(x)
        all_finite = bool(finite.all())
        same = x[1:] == x[:-1]
        valid = None if all_finite else finite[1:] & finite[:-1]
        if segment is None:
            joins = np.array([], dtype=np.int64)
            self.pairs += int(self.last == self.last and finite[0])
            self.repeats += int(self.last == x[0])
            self.last = x[-1]
        else:
            joins = np.arange(segment - 1, x.size - 1, segment)   # pairs across segments
        if valid is None:
            self.pairs += same.size - joins.size
            self.repeats += int(np.count_nonzero(same)) - int(np.count_nonzero(same[joins]))
        else:
            valid[joins] = False
            self.pairs += int(np.count_nonzero(valid))
            self.repeats += int(np.count_nonzero(same & valid))
        values = x if all_finite else x[finite]
        self.count += int(values.size)
        if values.size:
            self.lo, self.hi = min(self.lo, float(values.min())), max(self.hi,
                                                                      float(values.max()))
        if self.grid is not None:
            for i in range(0, values.size, _CHUNK):    # small temporaries (see Welch.add)
                self._on_grid(values[i:i + _CHUNK])

    def _on_grid(self, values):
        origin, step = self.grid
        t = values - origin
        t *= 1.0 / step
        k = np.rint(t)
        t -= k
        np.abs(t, out=t)
        off = t > GRID_TOL
        n_off = int(np.count_nonzero(off))
        self.off_grid += n_off
        if self.levels is not None:
            self.levels = np.union1d(self.levels, _distinct_ints(k[~off] if n_off else k))
            if self.levels.size > MAX_LEVELS:
                self.levels = None

    def on_grid(self):
        """Return True when the values lie on the grid found in the head."""
        return (self.grid is not None and self.count > 0
                and self.off_grid <= MAX_OFF_GRID * self.count)


def _distinct_ints(k):
    """Sorted distinct values of an integer-valued float array, as int64."""
    if k.size == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = float(k.min()), float(k.max())
    if hi - lo < 4 * k.size + 1024:
        k = k - lo
        return np.flatnonzero(np.bincount(k.astype(np.intp))).astype(np.int64) + int(lo)
    return np.unique(k.astype(np.int64))


def _find_grid(u):
    """
    Return (origin, step) when the sorted distinct values ``u`` lie on a grid, else None.

    The step is the smallest difference, refined by least squares over all values; it must be
    coarser than :data:`GRID_MIN_RELATIVE` of the largest magnitude and every value within
    :data:`GRID_TOL` steps of the grid.
    """
    if u.size < 2:
        return None
    scale = max(abs(float(u[0])), abs(float(u[-1])))
    step0 = float(np.min(np.diff(u)))
    if not step0 > GRID_MIN_RELATIVE * scale:
        return None
    rel = u - u[0]
    k = np.rint(rel / step0)
    if k[-1] > MAX_LEVELS:
        return None
    step = float(k @ rel / (k @ k))
    if np.max(np.abs(rel - k * step)) > GRID_TOL * step:
        return None
    return float(u[0]), step


def _axis_report(name, rate_hz, stats, welch, spacing):
    """One axis's :class:`AxisSensor` from its value statistics and Welch sums."""
    out = AxisSensor(axis=name, unit=sample_unit(name) if name in AXES else 'SI',
                     rate_hz=float(rate_hz), n_examined=stats.count,
                     segment_length=welch.length, segments=welch.count)
    if stats.pairs:
        out.repeated_fraction = stats.repeats / stats.pairs
    if stats.on_grid():
        out.resolution = stats.grid[1]
        out.off_grid_fraction = stats.off_grid / stats.count
        out.distinct_counted_over = stats.count
        out.distinct_values = (None if stats.levels is None
                               else int(stats.levels.size) + stats.off_grid)
    else:
        out.distinct_values, out.distinct_counted_over = stats.head_distinct, stats.head_count
    # a constant record has no noise to measure (its spectrum is rounding error)
    r0 = (_spectral(out, welch, spacing, rate_hz) if welch.count >= 2 and stats.hi > stats.lo
          else None)
    if out.resolution is not None and r0 is not None:
        q = out.resolution
        sigma = math.sqrt(max(r0 - q * q / 12.0, 0.0))
        out.noise_to_lsb = sigma / q
        out.quantization = 'fine' if sigma >= FINE_NOISE_LSB * q else 'coarse'
        if out.quantization == 'fine':
            out.quantization_density = q / math.sqrt(12.0 * rate_hz)
    return out


def _spectral(out, welch, spacing, rate_hz):
    """Fill lines, the white part and humps from the Welch sums; return R_0 or None."""
    psd = welch.psd(rate_hz)
    if not (np.all(np.isfinite(psd)) and np.any(psd[1:-1] > 0)):
        return None
    nu = welch.dof(spacing)
    out.lines, background, line_mask = find_lines(psd, nu, welch.length, rate_hz)
    white = fit_white(psd, nu, welch.length, rate_hz, line_mask, background)
    if white is None:
        return None
    out.humps = white.humps
    out.lag_correlation = tuple(float(v) for v in white.rho[:REPORTED_LAGS])
    out.lag_correlation_se = tuple(float(v) for v in white.rho_se[:REPORTED_LAGS])
    r = white.autocovariance
    out.filter_length = int(r.size - 1)
    out.white_autocovariance = tuple(float(v) for v in r)
    s, d = filter_sums(r)
    if s > 0:
        out.white_variance = float(s)
        out.bandwidth_hz = float(r[0] / s * rate_hz / 2.0)
        out.filter_moment = float(d / s)
    return float(r[0])
