"""
allan: live Allan deviation and noise coefficients of an IMU stream, with health diagnostics.

Subscribes ``imu/data_raw`` (sensor-data QoS, deep queue, overridable) and ``imu/temperature``
and publishes every ``publish_period`` seconds ``imu/allan_coeffs``, ``imu/allan_deviation``
(and ``imu/allan_deviation/<kind>`` per extra kind of ``estimators``), the figure on
``imu/allan_plot/compressed`` while subscribed (:mod:`.allan_plot`) and ``/diagnostics``; with
``covariance_topic`` set it republishes every message there with the live per-sample
variances patched in (:func:`imu_allan.formats.imu_cdr.set_covariance_diagonals`).  Layouts,
units and statuses: docs/interfaces.md (Topics) and docs/online.md (The allan node).

The node declares parameters (:mod:`.allan_parameters`), converts messages and publishes;
everything it computes is one :class:`imu_allan.core.live.session.LiveSession` (the estimate
of :class:`imu_allan.core.live.online.OnlineAllan`: stamp checks, stationarity gate,
bounded-memory overlapping Allan variance, fit; the publish cycles, advice and change test),
and :mod:`imu_allan.report.live_status` words its ``/diagnostics``.  ``analyze``'s online
option runs the same code, so the numbers agree for the same samples.

Messages are not handled one by one: the subscription sits in a callback group the executor
never waits on, and a timer takes the queued messages in batches (the executor costs about
200 us per message at 1 kHz otherwise), decoded and fed every ``FEED_PERIOD_S`` (0.25 s) and
before each publish cycle.
"""

import math
import time

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import Imu, Temperature
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

from .allan_parameters import (
    DESCRIPTION,
    drain_period,
    FEED_PERIOD_S,
    PARAMETERS,
    STEP_SHARE,
    TEMPERATURE_DEPTH,
)
from .allan_plot import PlotPublisher
from .common import (
    apply_changes,
    declare_parameter_table,
    diagnostic_status,
    log,
    node_main,
    polled_subscription,
    sensor_publisher,
    take_batch,
    validate_on_set,
)
from ..core.live.session import check_parameters, LiveSession
from ..core.live.streaming import parse_estimators
from ..core.units import AXES
from ..formats.imu_cdr import cdr_to_arrays, set_covariance_diagonals
from ..report.coeffs_layout import (
    adequacy_values,
    COEFF_LABELS,
    coefficient_table,
    DEVIATION_LABELS,
    deviation_table,
    limit_values,
)
from ..report.live_status import session_records


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
        self.session = LiveSession(self.params, lambda level, text: log(self, level, text))
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
        # The driver's imu/temperature, taken with the IMU messages: a subscription the
        # executor waits on would cost every drain's wake-up more (its wait set is built anew).
        self._temperature_sub = polled_subscription(self, Temperature, 'imu/temperature',
                                                    TEMPERATURE_DEPTH, overrides=False)
        self._pub_cov = (sensor_publisher(self, Imu, self.params['covariance_topic'])
                         if self.params['covariance_topic'] else None)
        self._cov_variance = None  # per-sample N^2 f per axis, once estimated
        self._plot = PlotPublisher(self)
        self._last_arrival = None
        self._step_budget = STEP_SHARE * drain_period(self.params)
        self._drain_timer = self.create_timer(drain_period(self.params), self.drain)
        self._publish_timer = self.create_timer(self.params['publish_period'],
                                                self.publish)
        rate = self.params['rate_hz']
        self.get_logger().info(
            f'waiting for imu/data_raw at {f"{rate:g} Hz" if rate else "a measured rate"}; '
            f'publishing every {self.params["publish_period"]:g} s; budget '
            f'{self.session.budget.source}'
            + (f'; estimator memory {self.session.pipeline.memory_bytes() / 1024:.0f} KiB (fixed)'
               if rate else ''))

    def close(self):
        """Stop the figure's worker thread (run_node calls this before destroy_node)."""
        self._plot.close()

    def _post_set(self, params):
        self._feed_pending()  # the samples taken before the change go where they went before
        changed = apply_changes(self.params, PARAMETERS, params)
        self.session.reconfigure(changed)
        if 'estimators' in changed:
            self._deviation_publishers()
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

    def drain(self):
        """Take every queued message, feed them every FEED_PERIOD_S, advance a publish cycle."""
        for msg in take_batch(self._temperature_sub, TEMPERATURE_DEPTH):
            self.session.temperature.add_message(msg)
        msgs = take_batch(self._sub, self._max_batch)
        if msgs:
            self._last_arrival = time.monotonic()
            self._pending += msgs
            if self._pub_cov is not None:
                self._republish(msgs)
            if self._last_arrival - self._fed_at >= FEED_PERIOD_S:
                self._feed_pending()
        if self.session.busy:
            self._advance()

    def _feed_pending(self):
        """Decode the gathered messages and feed them to the session in one batch."""
        self._fed_at = time.monotonic()
        if self._pending:
            msgs, self._pending = self._pending, []
            self.session.feed(*cdr_to_arrays(msgs))  # InputError (a measured rate misfits)

    def publish(self):
        """Start a publish cycle: freeze the sums; the steps run between drains."""
        self._feed_pending()  # the estimate of every sample taken so far
        if self.session.start_cycle():
            self._advance()

    def _advance(self):
        """Run session steps for a step budget; publish what a finished cycle gives."""
        pub = self.session.advance(self._step_budget)
        if pub is None:
            return
        if pub.result is not None:
            self._pub_dev.publish(multiarray(deviation_table(pub.result, AXES),
                                             DEVIATION_LABELS))
        for kind, curve in pub.deviations.items():  # mdev, ohdev: the same layout
            if curve is not None and kind in self._pub_kinds:
                self._pub_kinds[kind].publish(multiarray(deviation_table(curve, AXES),
                                                         DEVIATION_LABELS))
        if pub.fitted is not None:
            msg = multiarray(coefficient_table(pub.fitted, AXES), COEFF_LABELS)
            # after the table: each axis's adequacy p, then the upper limits
            msg.data.extend(adequacy_values(pub.fitted, AXES).tolist()
                            + limit_values(pub.fitted, AXES).tolist())
            self._pub_coeffs.publish(msg)
            self._cov_variance = pub.variance
        self._plot.offer(pub.result, pub.fitted)  # rendered off this thread, if subscribed
        self._feed_pending()  # the stream's counts of every sample taken so far
        self._pub_diag.publish(self._diagnostics())

    def _republish(self, msgs):
        """Each raw message on covariance_topic, its diagonals patched in bulk (bytes)."""
        if self._cov_variance is not None:
            msgs = set_covariance_diagonals(msgs, self._cov_variance)
        for blob in msgs:
            self._pub_cov.publish(blob)

    def _diagnostics(self):
        silence = (time.monotonic() - self._last_arrival
                   if self._last_arrival is not None else math.inf)
        records = session_records(self.session, silence, f'{self.get_name()}: ',
                                  self._plot.stats())
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        hw = self.params['hardware_id']
        for rec in records:
            array.status.append(diagnostic_status(rec.name, rec.level, rec.message, hw,
                                                  rec.values))
        return array
