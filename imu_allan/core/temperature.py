"""
Temperature: simulated temperature profiles, bias-versus-temperature slopes, temperature moves.

ROS-free.  Temperatures are in deg C (a difference of 1 deg C = 1 K); rates in SI (rad/s,
m/s^2); times in s.

* :class:`TemperatureProfile` -- what the simulated device's temperature does (constant, ramp,
  exponential warm-up); it drives a bias change of ``slope * (T - T_start)`` per axis.
* :func:`bias_slopes` -- per axis, the slope of the rate against temperature with its interval
  (method below).
* :func:`temperature_changes` -- where the temperature moved, so a report can tell whether a
  detected change or a warm-up coincides with one (:func:`coinciding_change`).

Slope method (:func:`bias_slopes`; docs/analyze.md, "temperature")
--------------------------------------------------------------------
Block means of the rate (:data:`N_BLOCKS` blocks by default) regressed on the temperature
interpolated at the block centres, ``b = S_xy / S_xx`` (:func:`regress_slopes`); the standard
error ``se`` is the spread of that slope over :data:`REPLICAS` simulations of the
:data:`SLOPE_TERMS` model fitted to the residuals (:func:`simulated_stderr`: correlated noise
makes the textbook ``sigma^2 / S_xx`` far too narrow), the white-noise one, with a note, when
that fit fails; the interval is ``b +- se`` (68.3 %, normal).

No term selection, because an uncertainty budget needs each contribution's estimate, not a
verdict on whether it is resolved: a BIC-selected model sets a term the record cannot resolve
to zero, and on a short record the flicker that moves the slope most is such a term.  Measured
on 36-s records at 100 Hz (thesis 3DM-GX3-25 noise, a 20 -> 40 deg C ramp over the first 30 s,
temperature every 0.5 s in 0.06 deg C steps, 60-120 seeds x 6 axes): with the selected model
(bias instability kept on 127 of 360 axes, though every axis has it) the normalised errors
(b - truth) / se had an rms of 1.3 (gyro) and 1.55 (accel), the 68.3 % interval covered the
truth in 59-64 % of cases; with :data:`SLOPE_TERMS` fitted, 0.99 and 1.04, 73 % (the true
model itself gives 1.13 and 1.03); with the simulator's own noise source (20-s blocks, 120
seeds) 1.00 and 0.99, covering 80 % and 76 % (heavier tails than a normal's).  No bias either
way (mean error -0.1 +- 0.07 se).  A rate ramp is left out of the fit: it adds no spread (a
drift that follows the temperature's course cannot be told from it; a temperature that goes up
and down separates them) and, fitted, takes over the long-term part of the random-walk terms
(rms 1.13 and 1.22 measured with all five IEEE terms).
"""

from dataclasses import asdict, dataclass
import math

import numpy as np

from .units import sample_unit

#: Default number of blocks the overlap of the records is cut into.
N_BLOCKS = 64
#: Fewest block means a slope is computed from.
MIN_BLOCKS = 8
#: Simulated replicas behind a slope's standard error (its relative precision is
#: 1/sqrt(2 (REPLICAS - 1)) = 5 %), and samples per block in them.
REPLICAS = 200
SUB_SAMPLES = 8
#: Noise terms fitted to the residuals for the standard error (module docstring: all of them,
#: no selection; quantization averages out in a block, a rate ramp adds no spread).
SLOPE_TERMS = ('white_noise', 'bias_instability', 'rate_random_walk')
#: Smallest temperature span (deg C) with a meaningful slope: a few ADC codes of the GX3-25
#: sensor (0.06 deg C each).
MIN_SPAN_C = 0.3
#: Default size of a temperature move, deg C, and the smoothing before it is looked for, s
#: (:func:`temperature_changes`).
CHANGE_THRESHOLD_C = 1.0
SMOOTH_S = 60.0


@dataclass(frozen=True)
class TemperatureProfile:
    """
    Temperature of a simulated device against time since power-up, deg C.

    ``kind``: ``constant`` (``start``), ``ramp`` (``start`` to ``end`` linearly over
    ``seconds``, then ``end``) or ``warmup`` (``end - (end - start) exp(-t / seconds)``, the
    exponential warm-up of a device in still air).
    """

    kind: str = 'constant'
    start: float = 25.0
    end: float = 25.0
    seconds: float = 1.0

    @classmethod
    def parse(cls, text):
        """
        Read ``constant:T``, ``ramp:T0:T1:SECONDS`` or ``warmup:T0:T1:TAU`` (deg C, s).

        Raise ValueError with a one-line reason.
        """
        parts = str(text).strip().split(':')
        kind = parts[0].strip().lower()
        want = {'constant': 1, 'ramp': 3, 'warmup': 3}
        if kind not in want or len(parts) - 1 != want[kind]:
            raise ValueError(f'temperature profile {text!r}: use constant:T, '
                             f'ramp:T0:T1:SECONDS or warmup:T0:T1:TAU (deg C, s)')
        try:
            values = [float(x) for x in parts[1:]]
        except ValueError:
            raise ValueError(f'temperature profile {text!r}: not a number') from None
        lo, hi = -40.0, 85.0      # the GX3-25 sensor's calibrated range (DCP-GX3 Eq. 16)
        temps = values[:1] if kind == 'constant' else values[:2]
        if not all(math.isfinite(v) and lo <= v <= hi for v in temps):
            raise ValueError(f'temperature profile {text!r}: temperatures must be in '
                             f'[{lo:g}, {hi:g}] deg C')
        if kind == 'constant':
            return cls('constant', values[0], values[0], 1.0)
        if not (math.isfinite(values[2]) and values[2] > 0):
            raise ValueError(f'temperature profile {text!r}: the time must be > 0 s')
        return cls(kind, *values)

    def at(self, t):
        """Temperature, deg C, at ``t`` s after power-up (scalar or array)."""
        t = np.maximum(np.asarray(t, dtype=np.float64), 0.0)
        if self.kind == 'ramp':
            out = self.start + (self.end - self.start) * np.minimum(t / self.seconds, 1.0)
        elif self.kind == 'warmup':
            out = self.end - (self.end - self.start) * np.exp(-t / self.seconds)
        else:
            out = np.full_like(t, self.start)
        return float(out) if out.ndim == 0 else out


def slope_unit(axis):
    """SI unit of a bias-versus-temperature slope: ``rad/s/K`` or ``m/s^2/K``."""
    return f'{sample_unit(axis)}/K'


@dataclass
class SlopeEstimate:
    """One axis: ``value`` and ``ci`` (68.3 %) in ``unit``, standard error, blocks used."""

    value: float
    ci: tuple
    unit: str
    stderr: float
    block_s: float
    n_blocks: int

    def to_json(self):
        """Plain dict for report.json."""
        return {**asdict(self), 'ci': list(self.ci)}


def block_means(t, data, rate_hz, block_s):
    """
    Means of ``data`` (n, A) over consecutive blocks of ``round(block_s * rate_hz)`` samples.

    Returns ``(centres, means)``: the mean time of each block (s) and the (nb, A) means; the
    incomplete last block is dropped.
    """
    m = max(1, int(round(block_s * rate_hz)))
    nb = data.shape[0] // m
    used = nb * m
    means = np.asarray(data[:used], dtype=np.float64).reshape(nb, m, -1).mean(axis=1)
    centres = np.asarray(t[:used], dtype=np.float64).reshape(nb, m).mean(axis=1)
    return centres, means


def regress_slopes(x, y):
    """
    Least-squares slopes of ``y`` (..., n, A) on ``x`` (..., n): ``S_xy / S_xx``, shape (..., A).

    Also returns the white-noise standard error ``sqrt(AVAR / S_xx)`` with the Allan variance
    of the residuals at lag one (NIST SP1065 eq. 7, tau = the block length).
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    xc = x - x.mean(axis=-1, keepdims=True)
    yc = y - y.mean(axis=-2, keepdims=True)
    sxx = np.sum(xc * xc, axis=-1)[..., None]
    slope = np.einsum('...n,...na->...a', xc, yc) / sxx
    resid = yc - xc[..., None] * slope[..., None, :]
    n = y.shape[-2]
    avar = np.sum(np.diff(resid, axis=-2) ** 2, axis=-2) / (2.0 * (n - 1))
    return slope, np.sqrt(avar / sxx)


def simulated_stderr(terms, x, block_s, replicas=REPLICAS, seed=0):
    """
    Spread of the slope on ``x`` of block means of the noise ``terms`` (one axis, SI).

    ``replicas`` series of ``len(x)`` blocks of ``block_s`` s, each simulated at
    :data:`SUB_SAMPLES` samples per block (block means keep the statistics of every term:
    white noise averages to ``N^2 / block_s``, flicker and random walks are low-frequency).
    """
    from .simulation.simulate import simulate_axis
    rng = np.random.default_rng(seed)
    nb = len(x)
    rate = SUB_SAMPLES / block_s
    series = np.stack([simulate_axis(terms, nb * SUB_SAMPLES, rate, rng)
                       for _ in range(replicas)])
    means = series.reshape(replicas, nb, SUB_SAMPLES).mean(axis=2)[..., None]
    slopes, _ = regress_slopes(np.broadcast_to(x, (replicas, nb)), means)
    return float(np.std(slopes[:, 0], ddof=1))


def bias_slopes(t, data, rate_hz, axes, temp_t, temp_c, block_s=None, replicas=REPLICAS,
                seed=0):
    """
    Bias-versus-temperature slope per axis (module docstring: method and its limits).

    ``t`` (n,) s, ``data`` (n, A) SI (evenly sampled at ``rate_hz``); ``temp_t``/``temp_c``
    the temperature record (s, deg C) on the same clock; ``block_s`` the block length
    (default: the overlap / :data:`N_BLOCKS`).  Returns ``({axis: SlopeEstimate}, notes)``:
    an empty dict and a one-line reason when the records do not allow a slope.
    """
    from .allan.estimate import allan_deviation
    from .fit import fit_noise_model, FitError
    from .sensor.measure import measure_sensor
    temp_t = np.asarray(temp_t, dtype=np.float64)
    temp_c = np.asarray(temp_c, dtype=np.float64)
    order = np.argsort(temp_t, kind='stable')
    temp_t, temp_c = temp_t[order], temp_c[order]
    if temp_t.size < 2:
        return {}, ['fewer than two temperature readings']
    t = np.asarray(t, dtype=np.float64)
    lo, hi = max(t[0], temp_t[0]), min(t[-1], temp_t[-1])
    inside = np.flatnonzero((t >= lo) & (t <= hi))
    if hi <= lo or inside.size < 2:
        return {}, ['the temperature and IMU records do not overlap in time']
    t = t[inside[0]:inside[-1] + 1]
    data = np.asarray(data[inside[0]:inside[-1] + 1], dtype=np.float64)
    block_s = float(block_s or (t[-1] - t[0]) / N_BLOCKS)
    centres, means = block_means(t, data, rate_hz, block_s)
    if centres.size < MIN_BLOCKS:
        return {}, [f'{centres.size} blocks of {block_s:.3g} s in the overlap of the records '
                    f'(need {MIN_BLOCKS})']
    x = np.interp(centres, temp_t, temp_c)
    if np.ptp(x) < MIN_SPAN_C:
        return {}, [f'the temperature moved by {np.ptp(x):.2f} deg C only (under '
                    f'{MIN_SPAN_C} deg C): no slope']
    slopes, white_se = regress_slopes(x, means)
    # The residual noise: the rate minus the temperature effect, at the sample level.
    temp_at = np.interp(t, temp_t, temp_c)
    resid = data - np.outer(temp_at - temp_at.mean(), slopes)
    notes = []
    model = None
    try:
        # (the sensor's filter shapes the shortest averaging times: the fit must know it)
        model = fit_noise_model(allan_deviation(resid, rate_hz, axes=tuple(axes)),
                                terms=SLOPE_TERMS,
                                processing=measure_sensor(resid, rate_hz, axes).processing()
                                ).model
    except (FitError, ValueError) as exc:
        notes.append(f'noise fit of the residuals failed ({exc}): white-noise intervals')
    out = {}
    for j, axis in enumerate(axes):
        terms = model.terms.get(axis) if model is not None else None
        if terms:
            se = simulated_stderr(terms, x, block_s, replicas, seed + j)
        else:
            se = float(white_se[j])
            if model is not None:
                notes.append(f'{axis}: no noise term fitted: white-noise interval')
        value = float(slopes[j])
        out[axis] = SlopeEstimate(value, (value - se, value + se), slope_unit(axis), se,
                                  block_s, int(centres.size))
    return out, notes


@dataclass
class TemperatureChange:
    """A move of the temperature from ``from_c`` to ``to_c``, from ``t_start_s`` to ``t_end_s``."""

    t_start_s: float
    t_end_s: float
    from_c: float
    to_c: float

    def to_json(self):
        """Plain dict for report.json."""
        return asdict(self)


def moving_average(t, values, width_s):
    """
    Mean of the readings within ``width_s / 2`` s of each reading's time (``t`` sorted).

    Near the ends the window is one-sided (it keeps its width, so the noise stays averaged;
    a trend that starts with the record is flattened there by up to ``width_s / 2`` s).
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if width_s <= 0 or v.size < 2:
        return v.copy()
    sums = np.concatenate(([0.0], np.cumsum(v)))
    lo = np.searchsorted(t, t - width_s / 2.0, side='left')
    hi = np.searchsorted(t, t + width_s / 2.0, side='right')
    return (sums[hi] - sums[lo]) / (hi - lo)


def temperature_changes(t, temp_c, threshold_c=CHANGE_THRESHOLD_C, settle=0.1,
                        smooth_s=SMOOTH_S):
    """
    Where the temperature moved by at least ``threshold_c`` deg C.

    The readings are first averaged over ``smooth_s`` s, at most a twentieth of the record (a
    centred moving mean: sensor noise and ADC steps would otherwise make swings of their
    own).  Then a zig-zag (swing) detector:
    a move is a monotone run between two turning points that differ by ``threshold_c`` or
    more; smaller reversals do not end a move.  Each move's span is from the last time the
    smoothed temperature was within ``settle`` of the move of its starting level to the first
    time it was within ``settle`` of its final level (the 10-90 % span by default; a warm-up
    ends where it is within 10 % of its rise from its plateau).  ``t`` in s (sorted),
    ``temp_c`` deg C; returns a list of :class:`TemperatureChange` in time order, levels
    smoothed.
    """
    t = np.asarray(t, dtype=np.float64)
    span = float(t[-1] - t[0]) if t.size else 0.0
    v = moving_average(t, temp_c, min(smooth_s, span / 20.0))
    n = v.size
    moves = []
    if n < 2:
        return moves
    pivot = ext = 0
    lo = hi = 0
    direction = 0
    for i in range(1, n):      # a small topic (1 Hz): a plain loop is fine
        vi = v[i]
        if direction == 0:
            if vi < v[lo]:
                lo = i
            if vi > v[hi]:
                hi = i
            if vi - v[lo] >= threshold_c:
                pivot, ext, direction = lo, i, 1
            elif v[hi] - vi >= threshold_c:
                pivot, ext, direction = hi, i, -1
        elif (vi - v[ext]) * direction > 0:
            ext = i
        elif (v[ext] - vi) * direction >= threshold_c:
            moves.append((pivot, ext))
            pivot, ext, direction = ext, i, -direction
    if direction:
        moves.append((pivot, ext))
    out = []
    for a, b in moves:
        span = v[b] - v[a]
        tol = abs(span) * settle
        seg = v[a:b + 1]
        near_start = np.flatnonzero(np.abs(seg - v[a]) <= tol)
        near_end = np.flatnonzero(np.abs(seg - v[b]) <= tol)
        start = a + int(near_start[near_start < near_end[0]].max()) \
            if np.any(near_start < near_end[0]) else a
        end = a + int(near_end[0])
        out.append(TemperatureChange(float(t[start]), float(t[end]), float(v[a]), float(v[b])))
    return out


def coinciding_change(t_s, changes, margin_s=0.0):
    """Index of the temperature change whose span (widened by ``margin_s``) holds ``t_s``."""
    for i, ch in enumerate(changes):
        if ch.t_start_s - margin_s <= t_s <= ch.t_end_s + margin_s:
            return i
    return None


class TemperatureRange:
    """
    Lowest and highest temperature over the span an online estimate covers (ROS-free).

    ``window_s`` > 0: only readings stamped within ``window_s`` s of the newest (the allan
    node's sliding window); 0: every reading since the last :meth:`reset`.  Readings are
    deg C with stamps in s.
    """

    def __init__(self, window_s=0.0):
        """Start empty."""
        from collections import deque
        self.window_s = float(window_s or 0.0)
        self._recent = deque()
        self.reset()

    def reset(self):
        """Forget every reading (the estimate restarted)."""
        self._recent.clear()
        self.low = self.high = math.nan
        self.count = 0

    def add(self, t_s, celsius):
        """Take one reading (non-finite values are ignored)."""
        if not math.isfinite(celsius):
            return
        self.count += 1
        if self.window_s > 0:
            recent = self._recent
            recent.append((t_s, celsius))
            while recent and recent[0][0] < t_s - self.window_s:
                recent.popleft()
            values = [c for _, c in recent]
            self.low, self.high = min(values), max(values)
        elif self.count == 1:
            self.low = self.high = celsius
        else:
            self.low, self.high = min(self.low, celsius), max(self.high, celsius)

    def add_message(self, msg):
        """Take a ``sensor_msgs/Temperature`` (rclpy or rosbags object: the same fields)."""
        stamp = msg.header.stamp
        self.add(stamp.sec + stamp.nanosec * 1e-9, float(msg.temperature))

    def key_values(self):
        """``temperature_min_c`` and ``temperature_max_c`` (NaN before the first reading)."""
        return {'temperature_min_c': float(self.low), 'temperature_max_c': float(self.high)}
