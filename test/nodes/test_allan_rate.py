"""
The allan node finds its own rate: a 400 Hz stream, no rate_hz given, over real DDS.

tau0 comes from the median stamp spacing over the first 2 s (RateFinder); the samples of those
seconds are held and fed afterwards, so the published coefficients equal ``analyze --online``'s
(:func:`imu_allan.core.analysis.analyze_samples`, whose rate is the median spacing of the whole
record) on exactly the same samples.  RELIABLE QoS so that no sample is lost on the way.
"""

import math
import os
import time

from conftest import executable, NodeRun, spin_until
from imu_allan.core.analysis import AnalysisOptions, analyze_samples
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulate import simulate
from imu_allan.formats.imu_adapter import imus_to_arrays
from imu_allan.formats.samples import Samples
from imu_allan.report.coeffs_layout import coefficient_table
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

DOMAIN = (os.getpid() + 37) % 100 + 100
RATE = 400.0
N = 12000  # 30 s
MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.0e-4, 'bias_instability': 8.0e-4},
                              'accel': {'white_noise': 8.0e-4, 'bias_instability': 1.5e-3}})


def _messages(t, data):
    from sensor_msgs.msg import Imu
    msgs = []
    for ti, row in zip(t, data):
        msg = Imu()
        msg.header.stamp.sec = int(math.floor(ti))
        msg.header.stamp.nanosec = int(round((ti - math.floor(ti)) * 1e9))
        msg.orientation_covariance[0] = -1.0
        w, a = msg.angular_velocity, msg.linear_acceleration
        w.x, w.y, w.z, a.x, a.y, a.z = (float(v) for v in row)
        msgs.append(msg)
    return msgs


def test_measured_rate_equals_analyze():
    """No rate_hz: diagnostics report the measured 400 Hz, coefficients equal analyze's."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray

    data = simulate(MODEL, N, RATE, seed=5)
    data[:, 5] += 9.80665
    msgs = _messages(1_700_000_000.0 + np.arange(N) / RATE, data)
    t_seen, data_seen = imus_to_arrays(msgs)  # the stamps as the node decodes them
    analysis = analyze_samples(Samples(t=t_seen, data=data_seen), AnalysisOptions(online=True))
    expected = coefficient_table(analysis.fit)

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN)
    cmd = [executable('allan'), '--ros-args', '-p', 'publish_period:=1.0',
           '-p', 'queue_depth:=30000',
           '-p', 'qos_overrides./imu/data_raw.subscription.reliability:=reliable']
    with NodeRun(cmd, context, 'allan_rate_test', DOMAIN, shutdown_context=True) as run:
        node, executor = run.node, run.executor
        coeffs, diags = [], []
        node.create_subscription(Float64MultiArray, 'imu/allan_coeffs',
                                 lambda m: coeffs.append((time.monotonic(), m)), 10)
        node.create_subscription(DiagnosticArray, '/diagnostics',
                                 lambda m: diags.append((time.monotonic(), m)), 50)
        pub = node.create_publisher(Imu, 'imu/data_raw', QoSProfile(
            history=QoSHistoryPolicy.KEEP_LAST, depth=30000,
            reliability=QoSReliabilityPolicy.RELIABLE))
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 30)
        for i in range(0, N, 500):
            for msg in msgs[i:i + 500]:
                pub.publish(msg)
            executor.spin_once(timeout_sec=0.01)

        def stream(array):
            status = next(s for s in array.status if s.name.endswith('IMU stream'))
            return {kv.key: kv.value for kv in status.values}

        assert spin_until(executor, lambda: any(stream(m).get('samples_total') == str(N)
                                                for _, m in diags), 90), 'samples missing'
        done = time.monotonic()
        assert spin_until(executor, lambda: coeffs and coeffs[-1][0] > done
                          and diags[-1][0] > done, 30)
        values = stream(diags[-1][1])
        assert values['rate_source'] == 'measured'
        # 6 significant digits on /diagnostics; the float stamps' rounding moves the median
        # spacing by parts in 1e5, so 400 Hz is met within 1e-4 and analyze's rate exactly
        assert float(values['expected_rate_hz']) == pytest.approx(analysis.rate_hz, rel=1e-6)
        assert float(values['expected_rate_hz']) == pytest.approx(RATE, rel=1e-4)
        table = np.asarray(coeffs[-1][1].data).reshape(6, 5, 3)
        assert np.array_equal(np.isnan(table), np.isnan(expected))
        np.testing.assert_allclose(table, expected, rtol=1e-9, equal_nan=True)
        assert np.isfinite(table[:, 1, 0]).all(), 'white noise found on every axis'
    out = run.output
    assert 'Traceback' not in out, out
    assert 'sample rate 399.9' in out or 'sample rate 400' in out, out
