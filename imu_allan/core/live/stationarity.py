"""
Stationarity gate: find the still spans of an IMU stream (Allan analysis needs a still IMU).

ROS-free, streaming, bounded memory.  The stream is cut into windows of ``window_s`` seconds
(counted in samples from the start of the stream, so decisions do not depend on how the stream
is chunked).  A window is *raw-moving* when, on any axis,

* its standard deviation exceeds ``std_factor`` x the noise floor of that axis (vibration,
  shaking), or
* its mean differs from the previous window's mean by more than ``step_factor`` x the floor x
  sqrt(2 / w) (w samples per window: that is the standard deviation of the difference of two
  window means of white noise, so ``step_factor`` = 8 is an 8-sigma test; it catches tilts,
  starts and stops that barely change the in-window spread), or
* the gyro magnitude of its mean exceeds ``gyro_max`` rad/s (a fast steady turn; no MEMS
  bias is that large), or
* its mean departs from the *still reference* (an exponential average of the means of still
  windows over ``reference_s`` seconds) by more than ``gyro_delta_max`` rad/s (gyro vector:
  slow steady turns, slow ramps that the step test misses) or ``accel_delta_max`` m/s^2
  (accelerometer vector: slow tilts), or by ``step_factor`` standard deviations of the window
  means' vector norm where that is more (never stricter than the noise: a static ADIS16405's
  accelerometer 0.2-s means crossed 0.05 m/s^2 about once a minute, and every crossing cost a
  second, 0.7 % of the record in short cuts that left no span longer than 250 s for the
  longest averaging times).  When the data stay quiet (no spread or step alarm) but away from
  the reference for ``settle_s`` seconds (accelerometer only: a new resting pose) or
  ``reacquire_s`` seconds (gyro: a persistent shift is taken for a bias change after that
  long), the reference jumps to the new level.

Every window statistic leaves out the window's most extreme sample per axis: a single spike is
not motion (motion moves every sample).  The noise floor of each axis is the
``floor_quantile`` quantile of the standard deviations of the last ``floor_windows`` windows
(moving or not), so it follows a real change of the noise level within a minute and stays
correct as long as the IMU is still for more than that share of the time.  A window is
finally excluded when it, the next window (motion starting inside it) or any of the ``hold_s``
seconds of windows before it was raw-moving (settling after motion).
Each decision therefore waits for the next window: the gate delays samples by one to two windows.
"""

from dataclasses import dataclass, replace
import math

import numpy as np

_FLOOR_EVERY = 8


@dataclass(frozen=True)
class GateOptions:
    """
    The tunables of :class:`StationarityGate`, each in the module docstring; SI: rad/s, m/s^2, s.

    ``min_floor``: lower bound of the floor (units of the samples) so constant or coarsely
    quantized signals do not divide by zero.  ValueError if out of range.
    """

    window_s: float = 0.2
    std_factor: float = 3.0
    step_factor: float = 8.0
    gyro_max: float = 0.1
    hold_s: float = 1.0
    floor_windows: int = 256
    floor_quantile: float = 0.2
    min_floor: float = 1e-9
    gyro_delta_max: float = 0.01
    accel_delta_max: float = 0.05
    reference_s: float = 30.0
    settle_s: float = 2.0
    reacquire_s: float = 60.0

    def __post_init__(self):
        """Refuse values the tests cannot use."""
        if (self.window_s <= 0 or self.std_factor <= 1 or self.step_factor <= 0
                or self.gyro_max <= 0):
            raise ValueError('window_s, step_factor and gyro_max must be > 0, std_factor > 1')
        if not 0 < self.floor_quantile < 1 or self.floor_windows < 4 or self.hold_s < 0:
            raise ValueError('need 0 < floor_quantile < 1, floor_windows >= 4, hold_s >= 0')


class StationarityGate:
    """
    Streaming motion detector; :meth:`update` returns the samples it has decided on.

    ``rate_hz`` in Hz; ``n_axes`` columns (6: gyro x/y/z rad/s, accel x/y/z m/s^2), of which
    ``gyro_columns`` hold angular rate; ``options`` the tunables (default
    :class:`GateOptions`'s), keyword arguments of the same names change single ones
    (``window_s=0.1``).
    """

    def __init__(self, rate_hz, n_axes=6, gyro_columns=(0, 1, 2), options=None, **changes):
        if not rate_hz or rate_hz <= 0:
            raise ValueError('rate_hz must be > 0')
        self.options = opt = replace(options or GateOptions(), **changes)
        self.rate_hz = float(rate_hz)
        self.n_axes = int(n_axes)
        self.gyro_columns = [c for c in gyro_columns if c < self.n_axes]
        self.accel_columns = [c for c in range(self.n_axes) if c not in self.gyro_columns]
        self.w = max(4, int(round(opt.window_s * rate_hz)))
        self.hold_windows = int(math.ceil(opt.hold_s * rate_hz / self.w))
        # Fixed-size state: the partial window, the window awaiting its decision, the ring of
        # window standard deviations for the floor.
        self._part = np.zeros((self.w, self.n_axes))
        self._part_n = 0
        self._held = np.zeros((self.w, self.n_axes))
        self._held_raw = None  # raw-moving flag of the held window; None when none is held
        self._ring = np.full((int(opt.floor_windows), self.n_axes), np.nan)
        self._ring_i = 0
        self._prev_mean = None
        self._since_raw = 10 ** 9  # windows since the last raw-moving one
        self._n_windows = 0
        self._floor_cache = None
        self._ref = None  # still reference (window means)
        self._ref_alpha = (min(1.0, self.w / (opt.reference_s * rate_hz))
                           if opt.reference_s > 0 else 1.0)
        self._settle_windows = max(1, int(math.ceil(opt.settle_s * rate_hz / self.w)))
        self._reacquire_windows = max(1, int(math.ceil(opt.reacquire_s * rate_hz / self.w)))
        self._deviant = 0  # consecutive quiet windows away from the reference
        self.n_decided = 0
        self.n_excluded = 0

    def memory_bytes(self):
        """Bytes held in numpy buffers (constant for the life of the gate)."""
        return (self._part.nbytes + self._held.nbytes + self._ring.nbytes
                + self.n_axes * 8)  # + the reference vector

    @property
    def excluded_share(self):
        """Share of the decided samples that were excluded (0-1), NaN before any decision."""
        return self.n_excluded / self.n_decided if self.n_decided else math.nan

    @property
    def pending(self):
        """Return the samples received but not yet decided (at most two windows)."""
        return self._part_n + (self.w if self._held_raw is not None else 0)

    def recent(self, k):
        """
        Return the last ``k`` samples fed (k <= w), (k, n_axes), NaN rows where none yet.

        They are still held (the window awaiting its decision and the partial one).
        """
        if self._held_raw is not None:
            have = np.concatenate((self._held, self._part[:self._part_n]))
        else:
            have = self._part[:self._part_n]
        out = np.full((k, self.n_axes), np.nan)
        take = min(k, have.shape[0])
        if take:
            out[k - take:] = have[have.shape[0] - take:]
        return out

    def _floor(self):
        # The quantile is refreshed every _FLOOR_EVERY windows (counted from the start, so
        # still independent of chunking): it moves slowly and costs most of the gate's time.
        if self._floor_cache is None or self._n_windows % _FLOOR_EVERY == 0:
            filled = self._ring[np.isfinite(self._ring[:, 0])]
            if filled.shape[0] == 0:
                return None
            self._floor_cache = np.maximum(np.quantile(filled, self.options.floor_quantile,
                                                       axis=0), self.options.min_floor)
        return self._floor_cache

    def _raw_moving(self, mean, std):
        opt = self.options
        floor = self._floor()
        quiet = True
        if self.gyro_columns and np.linalg.norm(mean[self.gyro_columns]) > opt.gyro_max:
            quiet = False
        if floor is not None:
            if np.any(std > opt.std_factor * floor):
                quiet = False
            if self._prev_mean is not None:
                limit = opt.step_factor * floor * math.sqrt(2.0 / self.w)
                if np.any(np.abs(mean - self._prev_mean) > limit):
                    quiet = False
        if self._ref is None:
            self._ref = mean.copy()
        dev = mean - self._ref
        # never stricter than the window means' own scatter (module docstring)
        noise = (np.zeros(self.n_axes) if floor is None
                 else opt.step_factor * floor / math.sqrt(self.w))
        gyro_off = bool(self.gyro_columns) and (
            np.linalg.norm(dev[self.gyro_columns])
            > max(opt.gyro_delta_max, np.linalg.norm(noise[self.gyro_columns])))
        accel_off = bool(self.accel_columns) and (
            np.linalg.norm(dev[self.accel_columns])
            > max(opt.accel_delta_max, np.linalg.norm(noise[self.accel_columns])))
        moving = not quiet or gyro_off or accel_off
        if quiet and (gyro_off or accel_off):
            self._deviant += 1
            needed = self._reacquire_windows if gyro_off else self._settle_windows
            if self._deviant >= needed:
                self._ref[:] = mean  # a new resting pose (or a real bias change)
                self._deviant = 0
        else:
            self._deviant = 0
        if not moving:
            self._ref += self._ref_alpha * dev
        self._prev_mean = mean
        self._ring[self._ring_i] = std
        self._ring_i = (self._ring_i + 1) % self._ring.shape[0]
        self._n_windows += 1
        return moving

    def _decide_held(self, next_raw, out_data, out_mask):
        """Decide the held window (``next_raw``: its successor's flag); return it is still."""
        self._since_raw = 0 if self._held_raw else self._since_raw + 1
        moving = next_raw or self._since_raw <= self.hold_windows
        out_data.append(self._held.copy())
        out_mask.append(np.full(self.w, not moving))
        self.n_decided += self.w
        self.n_excluded += self.w if moving else 0
        return not moving

    def _complete_window(self, window, mean, std, out_data, out_mask):
        raw = self._raw_moving(mean, std)
        if self._held_raw is not None:
            self._decide_held(raw, out_data, out_mask)
        self._held[:] = window
        self._held_raw = raw

    def update(self, block):
        """
        Feed samples (n, n_axes); return ``(data, still)`` for the samples now decided.

        The returned samples are the input delayed by one to two windows, in order;
        ``still`` (bool) is True where the sample may enter the Allan estimate.
        """
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        out_data, out_mask = [], []
        i, n = 0, block.shape[0]
        if self._part_n:
            take = min(self.w - self._part_n, n)
            self._part[self._part_n:self._part_n + take] = block[:take]
            self._part_n += take
            i = take
            if self._part_n == self.w:
                # Same reduction layout as the whole-window path below (same rounding).
                mean, std = _window_stats(self._part.reshape(1, self.w, self.n_axes))
                self._complete_window(self._part, mean[0], std[0], out_data, out_mask)
                self._part_n = 0
        k = (n - i) // self.w
        if k:
            # Whole windows straight from the block: statistics for all of them at once.
            windows = block[i:i + k * self.w].reshape(k, self.w, self.n_axes)
            means, stds = _window_stats(windows)
            for j in range(k):
                self._complete_window(windows[j], means[j], stds[j], out_data, out_mask)
            i += k * self.w
        if i < n:
            self._part[:n - i] = block[i:]
            self._part_n = n - i
        return self._output(out_data, out_mask)

    def flush(self):
        """
        Decide everything still pending (end of a record); return ``(data, still)``.

        The held window is decided without a successor; a partial last window takes the
        decision of its predecessor.
        """
        out_data, out_mask = [], []
        last_still = True
        if self._held_raw is not None:
            last_still = self._decide_held(False, out_data, out_mask)
            self._held_raw = None
        if self._part_n:
            out_data.append(self._part[:self._part_n].copy())
            out_mask.append(np.full(self._part_n, last_still))
            self.n_decided += self._part_n
            self.n_excluded += 0 if last_still else self._part_n
            self._part_n = 0
        return self._output(out_data, out_mask)

    def _output(self, out_data, out_mask):
        if not out_data:
            return np.zeros((0, self.n_axes)), np.zeros(0, bool)
        return np.concatenate(out_data), np.concatenate(out_mask)


def _window_stats(windows):
    """
    Per window (k, w, A): the mean and standard deviation without its most extreme sample.

    The tests' statistics (module docstring): one spike leaves them where the noise is.
    """
    w = windows.shape[1]
    sums = windows.sum(axis=1)
    extreme = np.take_along_axis(
        windows, np.abs(windows * w - sums[:, None, :]).argmax(axis=1)[:, None, :],
        axis=1)[:, 0]
    rest = (sums - extreme) / (w - 1)
    rest_sq = (np.einsum('kwa,kwa->ka', windows, windows) - extreme * extreme) / (w - 1)
    return rest, np.sqrt(np.maximum(rest_sq - rest * rest, 0.0))


def stationary_mask(data, rate_hz, **options):
    """
    Mask of the still samples of a whole record; return ``(still, excluded_share)``.

    ``data`` (n, A) in SI units with gyro columns first (the package axis order); ``options``
    are :class:`StationarityGate` parameters.
    """
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    gate = StationarityGate(rate_hz, n_axes=data.shape[1], **options)
    _, m1 = gate.update(data)
    _, m2 = gate.flush()
    still = np.concatenate([m1, m2])
    return still, gate.excluded_share
