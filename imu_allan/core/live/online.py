"""
The online pipeline the allan node runs, and the staged publish cycle.

Stamp checks -> stationarity gate -> streaming
Allan variance (:mod:`imu_allan.core.live.streaming`) -> fit.

``analyze --online`` runs the same code through :func:`online_allan`, so the numbers agree
with the node's for the same samples.
"""

import math

import numpy as np

from .health import Health, RATE_SETTLE_S, RateFinder, STALE, StampMonitor, stream_health
from .stationarity import StationarityGate
from .streaming import StreamingAllan
from ..allan.estimate import AllanResult
from ..fit import fit_noise_model, FitError, FittedModel
from ..sensor.measure import SensorAccumulator
from ..units import AXES, is_gyro, physical_limits
from ...errors import InputError


class OnlineAllan:
    """
    The online pipeline: stamp checks -> stationarity gate -> streaming Allan -> fit.

    ROS-free; the allan node feeds it message batches and ``online_allan`` feeds it a whole
    record, so both produce the same numbers for the same samples.

    ``rate_hz`` (Hz): the configured sample rate; 0 or None: measured from the stamps
    (:class:`~imu_allan.core.live.health.RateFinder`, median spacing over the first
    ``settle_s`` seconds), the samples of those seconds held and fed once it is known.
    ``gate`` leaves moving spans out (:class:`~imu_allan.core.live.stationarity.StationarityGate`
    with ``gate_options``); a stamp spacing above ``gap_factor`` sample intervals restarts the
    phase.  ``terms``: the terms to fit (default: automatic selection).  ``sensor``: measure
    the sensor's processing from the still samples
    (:class:`~imu_allan.core.sensor.measure.SensorAccumulator`) and fit where it does not shape
    the curve; ``filter_window_s`` (s), when not 0, is the IMU's own moving-average length
    (the 3DM-GX3-25's 0xDB window / 1000 Hz) and replaces the measured filter in the fit.
    ``estimator_options``: :class:`StreamingAllan` parameters (max_tau, window_s, ...).
    """

    def __init__(self, rate_hz, axes=AXES, gate=True, gate_options=None, gap_factor=1.5,
                 terms=None, settle_s=RATE_SETTLE_S, sensor=True, filter_window_s=0.0,
                 **estimator_options):
        self.axes = tuple(axes)
        self.filter_window_s = float(filter_window_s)
        self.terms = terms
        self.measure = sensor
        self.sensor = None
        self._limits = np.asarray(physical_limits(self.axes))
        self.rejected_total = np.zeros(len(self.axes), np.int64)  # per axis, since the start
        self.bad_stamps = 0  # samples whose stamp is no time (left out before everything)
        self._rejected_recent = np.zeros(len(self.axes), np.int64)  # since take_rejected()
        # Rejected values in flight through the gate: (stream indices of the samples, their
        # per-axis flags); the gate returns samples in order, counted by _n_gated.
        self._bad_in_gate = []
        self._n_gated = [0, 0]  # samples into and out of the gate
        self._setup = (gate, gate_options, gap_factor, estimator_options)
        self.rate_source = 'configured' if rate_hz else 'measured'
        self.rate_hz = self.estimator = self.monitor = self.gate = None
        self.finder = None if rate_hz else RateFinder(settle_s)
        if rate_hz:
            self._start(rate_hz)

    def _start(self, rate_hz):
        """Build the stages for a known rate (Hz)."""
        gate, gate_options, gap_factor, estimator_options = self._setup
        if self.rate_source == 'measured':
            check_rate_options(rate_hz, estimator_options.get('max_tau', math.inf),
                               estimator_options.get('window_s', 0.0),
                               estimator_options.get('min_clusters', 2),
                               (gate_options or {}).get('window_s') if gate else None)
        self.rate_hz = float(rate_hz)
        self.estimator = StreamingAllan(rate_hz, self.axes, **estimator_options)
        if self.measure:
            self.sensor = SensorAccumulator(rate_hz, self.axes)
        self.monitor = StampMonitor(rate_hz, gap_factor)
        if gate:
            gyro_columns = [i for i, a in enumerate(self.axes) if is_gyro(a)]
            self.gate = StationarityGate(rate_hz, len(self.axes), gyro_columns,
                                         **(gate_options or {}))
            # Per-sample tags that travel with the samples through the gate's delay: the
            # stamp-gap break, then the per-axis rejection flags.
            self._gate_breaks = _TagDelay(self.gate.w)

    def memory_bytes(self):
        """Bytes held in numpy buffers by the estimator and the gate (fixed)."""
        if self.estimator is None:
            return 0
        extra = self.gate.memory_bytes() + self._gate_breaks.memory_bytes() if self.gate else 0
        return self.estimator.memory_bytes() + extra

    @property
    def excluded_share(self):
        """Share of samples the gate left out (NaN with no gate or no decision yet)."""
        return self.gate.excluded_share if self.gate is not None else math.nan

    def feed(self, t, data):
        """Add samples with header stamps ``t`` (s, (n,)) and ``data`` (n, A) in SI units."""
        data = np.asarray(data, dtype=float)
        if data.ndim == 1:
            data = data[:, None]
        if t is not None:
            t = np.asarray(t, dtype=float)
            stamped = np.isfinite(t)  # a damaged stamp (nanosec >= 1e9 decodes as NaN)
            if not stamped.all():
                self.bad_stamps += int((~stamped).sum())
                t, data = t[stamped], data[stamped]
        if self.estimator is None:
            if t is None:
                raise ValueError('a measured rate (rate_hz 0) needs the time stamps')
            if self.finder.add(t, data) is None:
                return
            self._start(self.finder.rate_hz)
            t, data = self.finder.take()
        if t is None:
            keep, brk = np.ones(data.shape[0], bool), np.zeros(data.shape[0], bool)
        else:
            keep, brk = self.monitor.check(t)
        data, brk = data[keep], brk[keep]
        if data.shape[0] == 0:
            return
        bad = self._reject_nonphysical(data)
        if self.gate is None:
            self.estimator.update(data, None if bad is None else ~bad, brk)
            self._measure(data, None if bad is None else ~bad.any(axis=1))
            return
        n_in, n_out = self._n_gated
        if bad is not None:
            data = self._stand_in(data, bad)
            rows = np.flatnonzero(bad.any(axis=1))
            self._bad_in_gate.append((n_in + rows, bad[rows]))
        out, still = self.gate.update(data)
        brk_out = self._gate_breaks.push(brk, out.shape[0])
        self._n_gated = [n_in + data.shape[0], n_out + out.shape[0]]
        if not out.shape[0]:
            return
        use = still
        if self._bad_in_gate:  # per-axis use: the gate's decision and not rejected
            use = np.repeat(still[:, None], len(self.axes), axis=1)
            left = []
            for index, flags in self._bad_in_gate:
                here = index < n_out + out.shape[0]
                use[index[here] - n_out] &= ~flags[here]
                if not here.all():
                    left.append((index[~here], flags[~here]))
            self._bad_in_gate = left
        self.estimator.update(out, use, brk_out)
        self._measure(out, use if use.ndim == 1 else use.all(axis=1))

    def _measure(self, data, use):
        """Feed the sensor measurement the usable rows (still, every value physical)."""
        if self.sensor is not None:
            self.sensor.update(data if use is None else data[use])

    def sensor_report(self):
        """Return the sensor's processing measured so far (:class:`~.sensor.SensorReport`)."""
        return None if self.sensor is None else self.sensor.report()

    def _reject_nonphysical(self, data):
        """
        Find NaN, inf and non-physical values (``units.PHYSICAL_LIMIT``), per axis.

        Returns ``bad`` (n, A) bool, or None when every value is good.  A bad value is left
        out of its own axis only (:class:`StreamingAllan` per-axis masks: that axis's phase
        restarts after it, as at a stamp gap; the other axes keep the sample).  Counted per
        axis (:attr:`rejected_total`, :meth:`take_rejected`).
        """
        with np.errstate(invalid='ignore'):
            bad = ~(np.abs(data) <= self._limits)  # NaN compares False: caught too
        if not bad.any():
            return None
        counts = bad.sum(axis=0)
        self.rejected_total += counts
        self._rejected_recent += counts
        return bad

    def _stand_in(self, data, bad):
        """
        Return the samples for the motion gate: each bad value replaced by a stand-in.

        The stand-in is the same axis's value one gate window earlier (itself a stand-in if
        that was bad; why: docs/online.md, "Rejected values, per axis"), taken from what the
        gate holds (:meth:`StationarityGate.recent`); with no history yet, the axis's first
        good value in the batch, or 0.  The estimator never reads these values.
        """
        w = self.gate.w
        tail = self.gate.recent(w)
        x = np.concatenate((tail, data))
        missing = np.concatenate((np.isnan(tail), bad))
        for start in range(w, x.shape[0], w):  # each layer depends only on the one before
            block, hole = x[start:start + w], missing[start:start + w]
            if hole.any():
                block[hole] = x[start - w:start - w + block.shape[0]][hole]
                hole &= missing[start - w:start - w + block.shape[0]]
        if missing[w:].any():  # no history on an axis yet
            good = ~bad
            first = np.where(good.any(axis=0), data[np.argmax(good, axis=0),
                                                    np.arange(data.shape[1])], 0.0)
            x[w:] = np.where(missing[w:], first, x[w:])
        return x[w:]

    def take_rejected(self):
        """Per-axis counts of samples rejected since the last call ({axis: n}, non-zero only)."""
        recent = {a: int(n) for a, n in zip(self.axes, self._rejected_recent) if n}
        self._rejected_recent[:] = 0
        return recent

    def result(self, window=False):
        """Return the current :class:`~..allan.estimate.AllanResult` (None until enough data)."""
        return None if self.estimator is None else self.estimator.result(window=window)

    def stream_health(self, silence_s, timeout_s=2.0, rate_tolerance=0.1, name='IMU stream'):
        """
        Return the :func:`~imu_allan.core.live.health.stream_health` of the input.

        STALE while the rate is being measured; the values say whether tau0 was configured
        or measured.
        """
        if self.monitor is None:
            values = {'rate_source': self.rate_source, 'samples_held': self.finder.n_held,
                      'settle_s': self.finder.settle_s, 'silence_s': silence_s}
            return Health(name, STALE, f'measuring the sample rate from the stamps '
                                       f'({self.finder.n_held} samples so far)', values)
        health = stream_health(self.monitor, self.monitor.take_recent(), silence_s, timeout_s,
                               rate_tolerance, self.excluded_share, name=name,
                               rejected=self.take_rejected())
        health.values.update({'rate_source': self.rate_source, 'tau0_s': 1.0 / self.rate_hz,
                              'bad_stamps': self.bad_stamps})
        health.values.update({f'rejected_total.{a}': int(n)
                              for a, n in zip(self.axes, self.rejected_total) if n})
        if self.finder is not None:
            health.values['samples_dropped_before_rate'] = self.finder.n_dropped
        return health

    def deviations(self, window=False):
        """
        Return the extra streaming deviations, ``{kind: StreamingDeviation or None}``.

        One entry per kind of the ``estimators`` option other than oadev (mdev, ohdev);
        :meth:`result` is the OADEV with intervals.
        """
        est = self.estimator
        if est is None:
            return {}
        return {kind: est.deviation(kind, window) for kind in est.kinds if kind != 'oadev'}

    def processing(self):
        """Return ``{axis: Processing}`` for the fit (:meth:`SensorReport.processing`) or None."""
        report = self.sensor_report()
        return None if report is None else report.processing(self.filter_window_s or None)

    def fit(self, result, processing=None):
        """
        Fit the noise terms to a result; None when it has too few averaging times.

        ``processing``: the sensor's (default: :meth:`processing` now).
        """
        if result is None or result.tau.size < 2:
            return None
        try:
            return fit_noise_model(result, terms=self.terms,
                                   processing=processing or self.processing())
        except FitError:
            return None


def check_rate_options(rate_hz, max_tau, window_s, min_clusters, gate_window_s):
    """
    Raise InputError naming the first option that does not fit the sample rate (Hz).

    ``gate_window_s`` None: no gate.  The allan node checks a configured rate when it starts;
    :class:`OnlineAllan` checks a measured one when it is found.
    """
    at = f' at {rate_hz:.6g} Hz'
    if max_tau * rate_hz < 1.0:
        raise InputError('max_tau', 'shorter than one sample interval' + at)
    if window_s and window_s * rate_hz < 2 * min_clusters:
        raise InputError('window_s', f'too short: needs at least {2 * min_clusters} samples'
                                     + at)
    if gate_window_s is not None and gate_window_s * rate_hz < 4:
        raise InputError('gate_window_s', 'must span at least 4 samples' + at)


class StagedEstimate:
    """
    One estimate-and-fit cycle of an :class:`OnlineAllan`, in short steps.

    The sums are frozen when the cycle starts; each :meth:`step` (a few tens of ms) then does
    one axis's EDF and intervals, its fit, or its upper limits and budget lower ends
    (:meth:`~imu_allan.core.fit.FittedModel.alarm_low`), so a node can interleave them with
    taking messages.  Axes are independent, so :attr:`result` and :attr:`fitted` equal
    ``pipeline.result()`` and ``pipeline.fit(...)`` on the frozen data; :attr:`deviations`
    (the extra ``estimators``) are ready at once.
    """

    def __init__(self, pipeline, window=False):
        self.pipeline = pipeline
        est = pipeline.estimator
        snapshots = est.snapshots(window) if est is not None else {}
        self.snapshot = snapshots.get('oadev')
        self.deviations = {kind: est.deviation_from(kind, snap)
                           for kind, snap in snapshots.items() if kind != 'oadev'}
        self.result = None
        self.fitted = None
        #: the sensor's processing, measured once for the cycle (every axis's fit uses it)
        self.processing = pipeline.processing() if self.snapshot is not None else None
        self._parts = {}
        self._axis_fits = {}  # axis index -> its FittedModel (None: not fitted)
        self._fits = {}
        n_axes = len(pipeline.axes)
        self._queue = ([] if self.snapshot is None else
                       [(kind, j) for j in range(n_axes)
                        for kind in ('result', 'fit', 'limits')])

    @property
    def done(self):
        """Return True when every step has run."""
        return not self._queue

    def step(self):
        """Run the next step; return :attr:`done`."""
        if not self._queue:
            return True
        kind, j = self._queue.pop(0)
        est = self.pipeline.estimator
        if kind == 'result':
            self._parts[j] = est.result_from(self.snapshot, [j])
        elif kind == 'fit':
            self._axis_fits[j] = self.pipeline.fit(self._parts[j], self.processing)
            if self._axis_fits[j] is not None:
                self._fits.update(self._axis_fits[j].fits)
        elif self._axis_fits.get(j) is not None:  # kept with the axis's fit (AxisFit)
            fitted = self._axis_fits[j]
            for axis in fitted.axes:
                fitted.limits(axis)
                fitted.alarm_lows(axis)  # what the budget check reads (cached)
        if not self._queue:
            self._finish()
        return self.done

    def _finish(self):
        parts = [self._parts[j] for j in sorted(self._parts)]
        if not parts:
            return
        first = parts[0]

        def stack(name):
            return np.concatenate([getattr(p, name) for p in parts], axis=1)
        self.result = AllanResult(first.tau, first.m, stack('avar'), stack('adev'),
                                  stack('ci_low'), stack('ci_high'), stack('edf'),
                                  stack('alpha'), tuple(self.pipeline.axes), first.rate_hz,
                                  max(p.n_samples for p in parts))
        if self._fits:
            fits = {a: self._fits[a] for a in self.pipeline.axes if a in self._fits}
            self.fitted = FittedModel(fits, first.rate_hz, self.result)


class _TagDelay:
    """Delays per-sample flags by the gate's latency (the gate returns samples in order)."""

    def __init__(self, window):
        # The gate holds at most two windows; a ring of that size suffices.
        self._buf = np.zeros(2 * window + 1, bool)
        self._n = 0

    def memory_bytes(self):
        return self._buf.nbytes

    def push(self, flags, n_out):
        """Append ``flags``; pop the flags of the ``n_out`` oldest samples."""
        merged = np.concatenate((self._buf[:self._n], flags))
        rest = merged[n_out:]
        self._buf[:rest.size] = rest
        self._n = rest.size
        return merged[:n_out]


def run_online(data, rate_hz, t=None, axes=None, **options):
    """Feed a whole record through an :class:`OnlineAllan` (``options``: its own); return it."""
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    axes = tuple(axes) if axes is not None else AXES[:data.shape[1]]
    pipeline = OnlineAllan(rate_hz, axes, **options)
    pipeline.feed(t, data)
    return pipeline


def online_allan(data, rate_hz, t=None, axes=None, gate=True, gate_options=None,
                 gap_factor=1.5, window=False, **estimator_options):
    """
    Run the online estimator over a whole record; return an ``AllanResult`` (or None).

    The same code and defaults as the allan node: for the same samples (and options) the
    numbers equal what the node publishes.  ``data`` (n, A) in SI units; ``t`` (s) enables
    the stamp checks (out-of-order samples dropped, gaps restart the phase); ``gate`` leaves
    moving spans out (the last one to two gate windows, still undecided, are not included -
    as in the node); ``window`` returns the sliding-window estimate (needs ``window_s``).
    The other options are :class:`OnlineAllan`'s and :class:`StreamingAllan`'s.
    """
    pipeline = run_online(data, rate_hz, t, axes, gate=gate, gate_options=gate_options,
                          gap_factor=gap_factor, sensor=False, **estimator_options)
    return pipeline.result(window=window)
