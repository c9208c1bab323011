"""
allan: live Allan deviation and noise coefficients of an IMU stream, with health diagnostics.

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, sensor-data QoS with a deep queue, overridable)
and publishes every ``publish_period`` seconds:

* ``imu/allan_coeffs`` (std_msgs/Float64MultiArray): dims ``axis`` (6) x ``term`` (5:
  quantization, white_noise, bias_instability, rate_random_walk, rate_ramp) x ``stat`` (3:
  value, ci_low, ci_high; 68.3 %), row-major, data_offset 0, SI units, NaN where a term is not
  detected;
* ``imu/allan_deviation`` (std_msgs/Float64MultiArray): dims ``row`` (7: tau, gyro_x .. accel_z)
  x ``tau`` (T);
* ``imu/allan_deviation/<kind>`` for each other kind of the ``estimators`` parameter (``mdev``,
  ``ohdev``: streaming modified Allan and overlapping Hadamard deviations), the same layout;
* ``imu/allan_plot/compressed`` (sensor_msgs/CompressedImage, PNG): the Allan deviation figure,
  rendered in a worker thread only while something subscribes (:mod:`.allan_plot`);
* ``/diagnostics``: the stream (rate, gaps, out-of-order stamps, motion share), each axis
  against the noise budget (OK / WARN / ERROR / STALE) and the recording advice (OK when every
  precision target is met, WARN with the longest additional recording time otherwise;
  :mod:`imu_allan.core.fit.advisor`, recomputed every ``advice_period`` s in steps).

With ``covariance_topic`` set, every ``imu/data_raw`` message is also republished there as it
is drained, its angular-velocity and linear-acceleration covariance diagonals set to the live
per-sample variance N^2 rate_hz of the latest coefficients (robot_localization reads these),
patched in the serialized bytes (:func:`imu_allan.formats.imu_cdr.set_covariance_diagonals`);
with ``covariance_mode`` ``overbound``, N is the white noise whose Allan variance lies at or
above the measured upper 95 % bound at every published averaging time
(:func:`imu_allan.core.overbound.white_overbound`): conservative for a filter without bias
states.

The numerics are :class:`imu_allan.core.live.online.OnlineAllan` (stamp checks, stationarity
gate, bounded-memory overlapping Allan variance, fit): ``analyze``'s online option runs the same
code, so the numbers agree for the same samples.  Messages are not handled one by one: the
subscription sits in a callback group the executor never waits on, and a timer takes the queued
messages in batches (the executor costs about 200 us per message at 1 kHz otherwise), decoded
and fed every ``FEED_PERIOD_S`` (0.25 s) and before each publish cycle.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.qos_overriding_options import QoSOverridingOptions
from sensor_msgs.msg import Imu, Temperature
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from .allan_plot import PlotPublisher
from .common import (
    apply_changes,
    declare_parameter_table,
    diagnostic_status,
    node_main,
    Param,
    polled_subscription,
    take_batch,
    validate_on_set,
)
from ..core.fit.advisor import factor_grid_of, parse_targets, StagedAdvice
from ..core.live import health as hm
from ..core.live.change_monitor import ChangeMonitor
from ..core.live.online import check_rate_options, OnlineAllan, StagedEstimate
from ..core.live.streaming import parse_estimators
from ..core.model import NoiseModel
from ..core.temperature import TemperatureRange
from ..core.units import AXES, discrete_white_std, IEEE_TERMS, TERM_PARAMETERS
from ..errors import InputError
from ..formats.imu_cdr import cdr_to_arrays, set_covariance_diagonals
from ..report.advice import advice_statuses
from ..report.coeffs_layout import (
    adequacy_values,
    COEFF_LABELS,
    coefficient_table,
    DEVIATION_LABELS,
    deviation_table,
    limit_values,
)
from ..report.fit_quality import adequacy_health

DESCRIPTION = ('Live Allan deviation and noise coefficients (with 68.3 % intervals) of '
               'imu/data_raw: publishes imu/allan_coeffs, imu/allan_deviation and '
               '/diagnostics against a noise budget. Bounded memory; moving spans left out.')

#: The parameter table (nodes.common.Param: name, default, description, range, read-only).
PARAMETERS = [
    Param('rate_hz', 0.0, 'sample rate of imu/data_raw, Hz (tau0 = 1/rate_hz); 0 = measured '
                          'from the header stamps (median spacing over the first 2 s)',
          (0.0, 10000.0)),
    Param('filter_window_s', 0.0, 'length of the moving average the IMU applies before it '
                                  'outputs, s (3DM-GX3-25: the driver parameter filter_window '
                                  '/ 1000 Hz, shown on its /diagnostics); 0 = unknown: '
                                  'measured from the data', (0.0, 1.0), read_only=True),
    Param('publish_period', 10.0, 'seconds between publications (each cycle computes intervals '
                                  'and fits one axis at a time between message drains)',
          (0.1, 3600.0)),
    Param('window_s', 0.0, 'sliding window, s: publish the estimate of the last window_s seconds '
                           '(0 = the whole run)', (0.0, 1.0e7)),
    Param('max_tau', 10000.0, 'longest averaging time tracked, s (fixes the memory)',
          (0.001, 1.0e7)),
    Param('points_per_decade', 10, 'averaging times per decade', (1, 100)),
    Param('stride_base', 256, 'averaging factors up to this are exact; longer ones use every '
                              's-th overlapping term (docs/online.md)', (1, 10_000_000)),
    Param('min_clusters', 10, 'publish an averaging time once the data span min_clusters x tau',
          (2, 10000)),
    Param('estimators', ['oadev'], 'deviations computed (string array or comma list of oadev, '
                                   'mdev, ohdev; oadev always): each other kind is published on '
                                   'imu/allan_deviation/<kind>, same layout as '
                                   'imu/allan_deviation'),
    Param('gate', True, 'leave spans where the IMU moves out of the estimate'),
    Param('gate_window_s', 0.2, 'stationarity gate window, s', (0.005, 60.0)),
    Param('gate_std_factor', 3.0, 'motion if a window std exceeds this x the noise floor',
          (1.1, 1000.0)),
    Param('gate_step_factor', 8.0, 'motion if a window mean jumps by this many sigmas',
          (0.5, 1000.0)),
    Param('gate_gyro_max', 0.1, 'motion if the mean angular rate exceeds this, rad/s',
          (1.0e-6, 100.0)),
    Param('gate_hold_s', 1.0, 'seconds left out after motion (settling)', (0.0, 600.0)),
    Param('gap_factor', 1.5, 'a stamp spacing above this many sample intervals is a gap (the '
                             'phase restarts)', (1.01, 1000.0)),
    Param('terms', '', 'comma-separated terms to fit (empty: automatic among the five IEEE '
                       'terms)'),
    Param('budget_file', '', 'noise budget YAML (empty: the packaged 3DM-GX3-25 datasheet '
                             'budget)'),
    Param('model_file', '', 'noise model YAML for a model-vs-data discrepancy check (optional)'),
    Param('timeout_s', 2.0, 'ERROR on /diagnostics after this many seconds without samples',
          (0.01, 3600.0)),
    Param('rate_tolerance', 0.1, 'WARN when the measured rate differs by more than this fraction',
          (0.0, 10.0)),
    Param('hardware_id', '', 'hardware_id of the diagnostic statuses'),
    Param('covariance_topic', '', 'republish every imu/data_raw message here with the angular-'
                                  'velocity and linear-acceleration covariance diagonals set to '
                                  'the live per-sample variance N^2 rate_hz (the driver values '
                                  'until the first estimate; empty: off; read-only)',
          read_only=True),
    Param('covariance_mode', 'raw', 'covariance_topic variances: raw (N^2 rate_hz of the fitted '
                                    'white noise) or overbound (the white noise whose Allan '
                                    'variance is at or above the measured upper 95 % bound at '
                                    'every published averaging time; docs/exports.md)',
          choices=('raw', 'overbound')),
    Param('targets', '', 'recording advice targets TERM=REL,...: relative 68.3 % half-widths '
                         'over the defaults (white_noise=0.02, bias_instability=0.10, others '
                         '0.25)'),
    Param('advice_period', 60.0, 'seconds between recording-advice updates (each costs about '
                                 'a second of CPU, run in steps between drains)',
          (0.1, 86400.0)),
    Param('drain_period', 0.0, 'seconds between taking the queued messages (read-only); 0 = '
                               '0.1, or 0.05 with covariance_topic set (its republish delay)',
          (0.0, 1.0), read_only=True),
    Param('change_window_s', 600.0, 'change test window, s: dynamic Allan variance over windows '
                                    'of this length, step a quarter, each against the pooled '
                                    'baseline before it (docs/online.md); 0 = off',
          (0.0, 1.0e6)),
    Param('change_hold_s', 0.0, 'seconds (of header stamps) a change WARN lasts; 0 = until '
                                'change_reset is set', (0.0, 1.0e7)),
    Param('change_reset', False, 'any set of this parameter (true or false) clears the change '
                                 'WARNs and restarts the baselines'),
    Param('queue_depth', 5000, 'subscription queue depth, messages (read-only; >= rate x '
                               'drain_period x a margin)', (10, 1_000_000), read_only=True),
]
_DEFAULTS = {p.name: p.default for p in PARAMETERS}
#: Fewest samples in a change-test window (its longest tau is a tenth of it).
CHANGE_MIN_SAMPLES = 100
#: Default seconds between drains (:func:`drain_period`), without / with covariance_topic.
DRAIN_S, DRAIN_COVARIANCE_S = 0.1, 0.05
#: Seconds between feeds of the messages taken (decoded and fed in one batch): each numpy
#: call costs 5-15 us on the cache-cold data of a drain, so a quarter second of 50-ms drains
#: fed as one costs about 40 % as much (docs/benchmarks.md).  Everything taken is fed before
#: a publish cycle starts, before its diagnostics and before a parameter change: what is
#: published is the same.
FEED_PERIOD_S = 0.25
#: imu/temperature queue depth, messages (taken every drain; the driver sends 1 a second).
TEMPERATURE_DEPTH = 100
#: Longest stretch of publish-cycle work done in one drain callback, as a share of the drain
#: period (a step may overrun it): 20 ms of 50, 40 ms of 100, so a cycle and the advice take
#: the same wall time whatever the period.
STEP_SHARE = 0.4
# Parameters whose change restarts the estimate.
_RESTART = {'rate_hz', 'window_s', 'max_tau', 'points_per_decade', 'stride_base',
            'min_clusters', 'gate', 'gate_window_s', 'gate_std_factor', 'gate_step_factor',
            'gate_gyro_max', 'gate_hold_s', 'gap_factor'}
_RESTART |= {'estimators'}  # the new kinds' sums start with the estimate


def parse_terms(text):
    """Parse the ``terms`` parameter: None (automatic) or a list of known term names."""
    names = [t.strip() for t in str(text).split(',') if t.strip()]
    unknown = [t for t in names if t not in TERM_PARAMETERS]
    if unknown:
        raise InputError('terms', f'unknown noise term(s) {", ".join(unknown)} '
                                  f'(known: {", ".join(TERM_PARAMETERS)})')
    return names or None


def pipeline_options(p):
    """:class:`OnlineAllan` keyword arguments from a parameter dictionary."""
    gate_options = {'window_s': p['gate_window_s'], 'std_factor': p['gate_std_factor'],
                    'step_factor': p['gate_step_factor'], 'gyro_max': p['gate_gyro_max'],
                    'hold_s': p['gate_hold_s']}
    return {'rate_hz': p['rate_hz'], 'gate': p['gate'], 'gap_factor': p['gap_factor'],
            'terms': parse_terms(p['terms']), 'gate_options': gate_options,
            'max_tau': p['max_tau'], 'points_per_decade': p['points_per_decade'],
            'stride_base': p['stride_base'], 'min_clusters': p['min_clusters'],
            'window_s': p['window_s'], 'filter_window_s': p['filter_window_s'],
            'estimators': parse_estimators(p['estimators'])}


def check_parameters(p):
    """Cross-field checks on a full parameter dictionary; raise InputError with the reason."""
    if p['rate_hz']:  # a measured rate is checked by OnlineAllan once it is known
        check_rate_options(p['rate_hz'], p['max_tau'], p['window_s'], p['min_clusters'],
                           p['gate_window_s'] if p['gate'] else None)
        if 0 < p['change_window_s'] * p['rate_hz'] < CHANGE_MIN_SAMPLES:
            raise InputError('change_window_s', f'too short: needs at least '
                                                f'{CHANGE_MIN_SAMPLES} samples')
    from ..core.live.health import NoiseBudget
    from ..core.model import ModelError, NoiseModel
    parse_terms(p['terms'])
    parse_estimators(p['estimators'])
    parse_targets(p['targets'], 'targets')
    NoiseBudget.from_yaml(p['budget_file'] or None)
    if p['model_file']:
        try:
            NoiseModel.from_yaml(p['model_file'])
        except ModelError as exc:
            raise InputError('model_file', str(exc)) from None


def drain_period(p):
    """
    Seconds between drains: ``drain_period``, or with 0 the default for ``covariance_topic``.

    Each drain wakes the executor, whose wait set is built anew in Python every time (about
    1 ms of CPU on this machine's cache-cold data, docs/benchmarks.md): at 1 kHz 0.1 s costs
    a point and a half of a core less than 0.05 s.  A republished stream (``covariance_topic``)
    keeps 0.05 s, the delay a filter downstream sees.
    """
    if p['drain_period'] > 0:
        return p['drain_period']
    return DRAIN_COVARIANCE_S if p['covariance_topic'] else DRAIN_S


def multiarray(table, labels):
    """Return a row-major ``std_msgs/Float64MultiArray`` of a numpy array with dimension labels."""
    msg = Float64MultiArray()
    stride = int(table.size)
    for label, size in zip(labels, table.shape):
        msg.layout.dim.append(MultiArrayDimension(label=label, size=int(size), stride=stride))
        stride = stride // int(size) if size else 0
    msg.layout.data_offset = 0
    msg.data = table.astype(float).ravel().tolist()
    return msg


def main(args=None):
    """Entry point ``allan``."""
    node_main('allan', DESCRIPTION, PARAMETERS, AllanNode, args)


class AllanNode(Node):
    def __init__(self):
        super().__init__('allan')
        self.params = declare_parameter_table(self, PARAMETERS)
        check_parameters(self.params)  # InputError: main() prints it, exit status 2
        self._pending, self._fed_at = [], 0.0  # messages taken, not yet fed (FEED_PERIOD_S)
        self.budget = hm.NoiseBudget.from_yaml(self.params['budget_file'] or None)
        self._load_model()
        self.pipeline = OnlineAllan(axes=AXES, **pipeline_options(self.params))
        self.add_on_set_parameters_callback(validate_on_set(self.params, PARAMETERS,
                                                            check_parameters))
        self.add_post_set_parameters_callback(self._post_set)

        depth = int(self.params['queue_depth'])
        self._sub = polled_subscription(self, Imu, 'imu/data_raw', depth, raw=True)
        self._max_batch = depth
        self._pub_coeffs = self.create_publisher(Float64MultiArray, 'imu/allan_coeffs', 10)
        self._pub_dev = self.create_publisher(Float64MultiArray, 'imu/allan_deviation', 10)
        self._pub_kinds = {}  # imu/allan_deviation/<kind> of the other estimators
        self._deviation_publishers()
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # The temperature range the current estimate spans (the driver's imu/temperature),
        # taken with the IMU messages: a subscription the executor waits on would cost every
        # drain's wake-up more (its wait set is built anew each time).
        self._temperature = TemperatureRange(self.params['window_s'])
        self._temperature_sub = polled_subscription(self, Temperature, 'imu/temperature',
                                                    TEMPERATURE_DEPTH, overrides=False)
        self._pub_cov = self.create_publisher(
            Imu, self.params['covariance_topic'], qos_profile_sensor_data,
            qos_overriding_options=QoSOverridingOptions.with_default_policies()) \
            if self.params['covariance_topic'] else None
        self._cov_variance = None  # per-sample N^2 f per axis, once estimated
        self._limits = None  # the latest upper limits (axis, term) of the terms not resolved
        self._change = None  # the change test (core.live.change_monitor), once the rate is known
        self._plot = PlotPublisher(self)
        self._last_arrival = None
        self._cycle = None
        self._advice, self._advice_due = None, 0.0
        self._advice_statuses = advice_statuses(None, self._advice_name())
        self.last_cycle = {'cycle_total_s': math.nan, 'cycle_max_step_s': math.nan,
                           'cycle_wall_s': math.nan}
        self._step_budget = STEP_SHARE * drain_period(self.params)
        self._drain_timer = self.create_timer(drain_period(self.params), self.drain)
        self._publish_timer = self.create_timer(self.params['publish_period'],
                                                self.publish)
        rate = self.params['rate_hz']
        self.get_logger().info(
            f'waiting for imu/data_raw at {f"{rate:g} Hz" if rate else "a measured rate"}; '
            f'publishing every {self.params["publish_period"]:g} s; budget '
            f'{self.budget.source}'
            + (f'; estimator memory {self.pipeline.memory_bytes() / 1024:.0f} KiB (fixed)'
               if rate else ''))

    def close(self):
        """Stop the figure's worker thread (run_node calls this before destroy_node)."""
        self._plot.close()

    # -- parameters ------------------------------------------------------------------

    def _post_set(self, params):
        self._feed_pending()  # the samples taken before the change go where they went before
        changed = apply_changes(self.params, PARAMETERS, params)
        if changed & _RESTART or 'terms' in changed:
            if changed & _RESTART:
                self.get_logger().info('estimator settings changed: estimate restarted')
                self.pipeline = OnlineAllan(axes=AXES, **pipeline_options(self.params))
                self._temperature = TemperatureRange(self.params['window_s'])
                # A cycle of the old estimate is not published: finishing it would read the
                # new pipeline (its rate is None until measured: a TypeError, seen in tests).
                self._cycle = None
            else:
                self.pipeline.terms = parse_terms(self.params['terms'])
        if 'estimators' in changed:
            self._deviation_publishers()
        if 'budget_file' in changed:
            self.budget = hm.NoiseBudget.from_yaml(self.params['budget_file'] or None)
        if 'model_file' in changed:
            self._load_model()
        if changed & {'change_window_s', 'change_hold_s', 'change_reset'} or changed & _RESTART:
            self._change = None
            self._start_change()  # a fresh baseline, OK until a new change
        if 'publish_period' in changed:
            self._publish_timer.cancel()
            self.destroy_timer(self._publish_timer)
            self._publish_timer = self.create_timer(self.params['publish_period'],
                                                    self.publish)

    def _deviation_publishers(self):
        """One publisher per extra kind of ``estimators`` (made or destroyed on a change)."""
        kinds = [k for k in parse_estimators(self.params['estimators']) if k != 'oadev']
        for kind in [k for k in self._pub_kinds if k not in kinds]:
            self.destroy_publisher(self._pub_kinds.pop(kind))
        for kind in kinds:
            if kind not in self._pub_kinds:
                self._pub_kinds[kind] = self.create_publisher(
                    Float64MultiArray, f'imu/allan_deviation/{kind}', 10)

    # -- work ------------------------------------------------------------------------

    def drain(self):
        """Take every queued message, feed them every FEED_PERIOD_S, advance a publish cycle."""
        for msg in take_batch(self._temperature_sub, TEMPERATURE_DEPTH):
            self._temperature.add_message(msg)
        msgs = take_batch(self._sub, self._max_batch)
        if msgs:
            self._last_arrival = time.monotonic()
            self._pending += msgs
            if self._pub_cov is not None:
                self._republish(msgs)
            if self._last_arrival - self._fed_at >= FEED_PERIOD_S:
                self._feed_pending()
        if self._cycle is not None:
            self._advance_cycle()
        elif self._advice is not None:
            self._advance_advice()

    def _feed_pending(self):
        """Decode the gathered messages and feed them in one batch (estimate, change test)."""
        self._fed_at = time.monotonic()
        if not self._pending:
            return
        msgs, self._pending = self._pending, []
        t, data = cdr_to_arrays(msgs)
        started = self.pipeline.estimator is not None
        self.pipeline.feed(t, data)  # InputError (measured rate misfits): exit 2
        if not started and self.pipeline.estimator is not None:
            self.get_logger().info(
                f'sample rate {self.pipeline.rate_hz:.6g} Hz ({self.pipeline.rate_source});'
                f' estimator memory {self.pipeline.memory_bytes() / 1024:.0f} KiB (fixed)')
        self._feed_change(t, data)

    def _start_change(self):
        """Start the change test once the sample rate is known (off at change_window_s 0)."""
        if self._change is None and self.params['change_window_s'] and self.pipeline.rate_hz:
            self._change = ChangeMonitor(self.pipeline.rate_hz, self.params['change_window_s'],
                                         AXES, self.params['change_hold_s'])

    def _feed_change(self, t, data):
        """Feed the change test; log each change it finds."""
        self._start_change()
        if self._change is None:
            return
        for c in self._change.feed(t, data):
            self.get_logger().warn(f'{c.axis}: {c.what} changed at stamp {c.t_s:.3f} s '
                                   f'(ratio {c.ratio:.3g})')

    def publish(self):
        """Start a publish cycle: freeze the sums; the steps run between drains."""
        if self._cycle is not None:
            return  # the previous cycle is still running (publish_period very short)
        self._feed_pending()  # the estimate of every sample taken so far
        self._cycle = StagedEstimate(self.pipeline, window=self.params['window_s'] > 0)
        self._cycle_cpu = 0.0
        self._cycle_max_step = 0.0
        self._cycle_wall = time.monotonic()
        self._advance_cycle()

    def _advance_cycle(self):
        """Run cycle steps for up to a step budget, then publish once the cycle is done."""
        start = time.perf_counter()
        cycle = self._cycle
        while not cycle.done and time.perf_counter() - start < self._step_budget:
            t0 = time.perf_counter()
            cycle.step()
            self._cycle_max_step = max(self._cycle_max_step, time.perf_counter() - t0)
        if cycle.done:
            result, fitted = cycle.result, cycle.fitted
            if result is not None:
                self._pub_dev.publish(multiarray(deviation_table(result, AXES),
                                                 DEVIATION_LABELS))
            for kind, curve in cycle.deviations.items():  # mdev, ohdev: the same layout
                if curve is not None and kind in self._pub_kinds:
                    self._pub_kinds[kind].publish(multiarray(deviation_table(curve, AXES),
                                                             DEVIATION_LABELS))
            table = coefficient_table(fitted, AXES) if fitted is not None else None
            if table is not None:
                msg = multiarray(table, COEFF_LABELS)
                limits = limit_values(fitted, AXES)
                # after the table: each axis's adequacy p, then the upper limits
                msg.data.extend(adequacy_values(fitted, AXES).tolist() + limits.tolist())
                self._limits = limits.reshape(len(AXES), -1)
                self._pub_coeffs.publish(msg)
                # robot_localization reads per-message variances: N^2 f (NaN: keep the driver's)
                white = table[:, IEEE_TERMS.index('white_noise'), 0]
                if self.params['covariance_mode'] == 'overbound' and result is not None:
                    from ..core.overbound import white_overbound
                    white = white_overbound(result, AXES)
                self._cov_variance = discrete_white_std(white, self.pipeline.rate_hz) ** 2
            self._plot.offer(result, fitted)  # rendered off this thread, only if subscribed
            self._cycle = None
            self._cycle_cpu += time.perf_counter() - start
            self.last_cycle = {'cycle_total_s': self._cycle_cpu,
                               'cycle_max_step_s': self._cycle_max_step,
                               'cycle_wall_s': time.monotonic() - self._cycle_wall}
            self._start_advice(result, fitted)
            self._feed_pending()  # the stream's counts of every sample taken so far
            self._pub_diag.publish(self._diagnostics(result, table, fitted))
        else:
            self._cycle_cpu += time.perf_counter() - start

    def _republish(self, msgs):
        """Each raw message on covariance_topic, its diagonals patched in bulk (bytes)."""
        if self._cov_variance is not None:
            msgs = set_covariance_diagonals(msgs, self._cov_variance)
        for blob in msgs:
            self._pub_cov.publish(blob)

    def _start_advice(self, result, fitted):
        """Start the recording advice on a finished estimate (at most every advice_period)."""
        now = time.monotonic()
        if self._advice is not None or fitted is None or now < self._advice_due:
            return
        self._advice_due = now + self.params['advice_period']
        if self.params['window_s'] > 0:  # a sliding window does not grow with recording
            self._advice_statuses = [hm.Health(self._advice_name(), hm.OK,
                                               'no advice with a sliding window (window_s > 0)')]
            return
        est = self.pipeline.estimator
        self._advice = StagedAdvice(result, fitted, parse_targets(self.params['targets']),
                                    factor_grid_of(est.ms, est.min_clusters))

    def _advance_advice(self):
        """Advice steps for up to a step budget; its status is ready when they are done."""
        start = time.perf_counter()
        while not self._advice.step() and time.perf_counter() - start < self._step_budget:
            pass
        if self._advice.done:
            self._advice_statuses = advice_statuses(self._advice.advice, self._advice_name(),
                                                    f'{self.get_name()}: ')
            self._advice = None

    def _advice_name(self):
        return f'{self.get_name()}: recording advice'

    def _load_model(self):
        """Return the reference noise model for the discrepancy check (validated on set)."""
        self.model_file = self.params['model_file']
        self.model = NoiseModel.from_yaml(self.model_file) if self.model_file else None

    def _diagnostics(self, result, table, fitted=None):
        prefix = f'{self.get_name()}: '
        silence = (time.monotonic() - self._last_arrival
                   if self._last_arrival is not None else math.inf)
        p = self.pipeline
        stream = p.stream_health(silence, self.params['timeout_s'],
                                 self.params['rate_tolerance'], name=prefix + 'IMU stream')
        stream.values.update({
            'samples_used': p.estimator.n_used if p.estimator else 0,  # on at least one axis
            'samples_offered': p.estimator.n_offered if p.estimator else 0,
            'averaging_times': 0 if result is None else int(result.tau.size),
            'longest_tau_s': math.nan if result is None else float(result.tau[-1]),
            'estimator_memory_bytes': p.memory_bytes(),
            'estimators': ','.join(parse_estimators(self.params['estimators'])),
            'window_s': self.params['window_s'],
            'budget_file': self.budget.source,
            'model_file': self.model_file or '(none)',
            **self.last_cycle,
            **self._plot.stats(),
            **self._temperature.key_values(),
        })
        if p.estimator is not None:  # per axis where values were rejected (NaN, inf, ...)
            stream.values.update({f'samples_used.{a}': int(n) for a, n, r in zip(
                p.axes, p.estimator.n_used_axes, p.rejected_total) if r})
        records = [stream] + hm.budget_health(table, self.budget, AXES, prefix,
                                              self._limits if table is not None else None)
        records += adequacy_health(fitted, AXES, prefix)
        records += self._advice_statuses
        if self._change is not None:
            records += self._change.health(prefix)
        if self.model is not None:  # the discrepancy check: gap and effect per axis
            records += hm.discrepancy_health(self.model, result, AXES, prefix)
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        hw = self.params['hardware_id']
        for rec in records:
            array.status.append(diagnostic_status(rec.name, rec.level, rec.message, hw,
                                                  rec.values))
        return array
