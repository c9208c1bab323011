"""
A built ``allan`` node fed over real DDS by this process (shared by the live-view tests).

The node runs as a subprocess on the test process's own ROS_DOMAIN_ID with RELIABLE intake
(its QoS override parameters), so every sample arrives; this process publishes simulated
100 Hz Imu messages and keeps every ``/diagnostics`` array it sees.
"""

import math
import signal
import time

from conftest import executable, NodeRun, spin_until
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
import numpy as np

RATE = 100.0
MODEL = NoiseModel.from_dict({
    'gyro': {'white_noise': 5.0e-4, 'bias_instability': 8.0e-4},
    'accel': {'white_noise': 8.0e-4, 'bias_instability': 1.5e-3}})


def imu_messages(data, t):
    """sensor_msgs/Imu messages of samples ``data`` (n, 6) stamped ``t`` (s)."""
    from sensor_msgs.msg import Imu
    msgs = []
    for ti, row in zip(t, data):
        msg = Imu()
        sec = int(math.floor(ti))
        msg.header.stamp.sec = sec
        msg.header.stamp.nanosec = int(round((ti - sec) * 1e9))
        msg.header.frame_id = 'imu_link'
        msg.orientation_covariance[0] = -1.0
        w, a = msg.angular_velocity, msg.linear_acceleration
        w.x, w.y, w.z, a.x, a.y, a.z = (float(v) for v in row)
        msgs.append(msg)
    return msgs


def status_values(array, suffix):
    """Key-values of the status whose name ends with ``suffix`` (None if absent)."""
    for status in array.status:
        if status.name.endswith(suffix):
            return {kv.key: kv.value for kv in status.values}
    return None


class AllanClient(NodeRun):
    """
    The built ``allan`` node and a client that feeds it and records what it publishes.

    ``coeffs`` and ``diags`` collect ``(receive time, message)`` of ``imu/allan_coeffs`` and
    ``/diagnostics``; ``publish(msgs)`` sends Imu messages RELIABLE (the node's intake must
    be made reliable with its QoS override parameter, so that every sample arrives).
    """

    def __init__(self, cmd, context, client, domain=None, depth=20000, **options):
        """``depth``: the publisher's history (at least the messages sent in one go)."""
        super().__init__(cmd, context, client, domain, **options)
        self.depth = depth
        self.coeffs, self.diags = [], []

    def __enter__(self):
        """Start the node and the client; wait until the node subscribes."""
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
        from sensor_msgs.msg import Imu
        from std_msgs.msg import Float64MultiArray
        super().__enter__()
        self.node.create_subscription(Float64MultiArray, 'imu/allan_coeffs',
                                      lambda m: self.coeffs.append((time.monotonic(), m)), 10)
        self.node.create_subscription(DiagnosticArray, '/diagnostics',
                                      lambda m: self.diags.append((time.monotonic(), m)), 50)
        qos = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=self.depth,
                         reliability=QoSReliabilityPolicy.RELIABLE)
        self.pub = self.node.create_publisher(Imu, 'imu/data_raw', qos)
        assert self.spin_until(lambda: self.pub.get_subscription_count() > 0, 30), \
            'allan node did not subscribe'
        return self

    def spin_until(self, predicate, timeout):
        """Spin the client until ``predicate()``; False after ``timeout`` s."""
        return spin_until(self.executor, predicate, timeout)

    def publish(self, msgs):
        """Publish messages in bursts of 500, spinning the client between bursts."""
        for i in range(0, len(msgs), 500):
            for msg in msgs[i:i + 500]:
                self.pub.publish(msg)
            self.executor.spin_once(timeout_sec=0.01)

    def wait_counted(self, n, timeout=60):
        """Wait until the node's diagnostics count ``n`` samples; return the time (monotonic)."""
        def complete():
            return any((status_values(m, 'IMU stream') or {}).get('samples_total') == str(n)
                       for _, m in self.diags)
        assert self.spin_until(complete, timeout), 'the node never reported all samples'
        return time.monotonic()

    def wait_published_after(self, when, timeout=30):
        """Wait for coefficients and diagnostics published after ``when``; return the former."""
        assert self.spin_until(lambda: self.coeffs and self.coeffs[-1][0] > when + 0.01
                               and self.diags[-1][0] > when + 0.01, timeout)
        return self.coeffs[-1][1]


class AllanFeed(AllanClient):
    """Start the node, publish ``n`` samples to it, watch its diagnostics; use with ``with``."""

    def __init__(self, context, domain, n=6000, seed=3, params=()):
        """``params``: extra ``name:=value`` node parameters."""
        # Two fixed terms: automatic selection would take seconds per cycle on a loaded machine.
        cmd = [executable('allan'), '--ros-args', '-p', 'publish_period:=0.5',
               '-p', 'queue_depth:=20000', '-p', 'terms:=white_noise,bias_instability',
               '-p', 'qos_overrides./imu/data_raw.subscription.reliability:=reliable']
        for param in params:
            cmd += ['-p', param]
        super().__init__(cmd, context, f'allan_feed_{id(self)}', domain,
                         stop_signal=signal.SIGINT)
        self.n = n
        data = simulate(MODEL, n, RATE, seed=seed)
        data[:, 5] += 9.80665
        self.msgs = imu_messages(data, 1_700_000_000.0 + np.arange(n) / RATE)

    def feed(self):
        """Publish every sample, then wait until the node's diagnostics count them all."""
        self.publish(self.msgs)
        return self.wait_counted(self.n)
