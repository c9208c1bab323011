"""
The allan node finds its own rate: a 400 Hz stream, no rate_hz given, over real DDS.

tau0 comes from the median stamp spacing over the first 2 s (RateFinder); the samples of those
seconds are held and fed afterwards, so the published coefficients equal ``analyze --online``'s
(:func:`imu_allan.core.analysis.analyze_samples`, whose rate is the median spacing of the whole
record) on exactly the same samples.  RELIABLE QoS so that no sample is lost on the way.
"""

import math

from conftest import domain, executable
from imu_allan.core.analysis import AnalysisOptions, analyze_samples
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.imu_adapter import imus_to_arrays
from imu_allan.formats.samples import Samples
from imu_allan.report.coeffs_layout import coefficient_table
from nodes.allan_feed import AllanClient
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

DOMAIN = domain(1)  # not conftest's DOMAIN: a module of its own
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
    with AllanClient(cmd, context, 'allan_rate_test', DOMAIN, depth=30000,
                     shutdown_context=True) as run:
        coeffs, diags = run.coeffs, run.diags
        run.publish(msgs)

        def stream(array):
            status = next(s for s in array.status if s.name.endswith('IMU stream'))
            return {kv.key: kv.value for kv in status.values}

        run.wait_published_after(run.wait_counted(N, timeout=90))
        values = stream(diags[-1][1])
        assert values['rate_source'] == 'measured'
        # 6 significant digits on /diagnostics; the float stamps' rounding moves the median
        # spacing by parts in 1e5, so 400 Hz is met within 1e-4 and analyze's rate exactly
        assert float(values['expected_rate_hz']) == pytest.approx(analysis.rate_hz, rel=1e-6)
        assert float(values['expected_rate_hz']) == pytest.approx(RATE, rel=1e-4)
        table = np.asarray(coeffs[-1][1].data[:90]).reshape(6, 5, 3)
        assert np.array_equal(np.isnan(table), np.isnan(expected))
        np.testing.assert_allclose(table, expected, rtol=1e-9, equal_nan=True)
        assert np.isfinite(table[:, 1, 0]).all(), 'white noise found on every axis'
    out = run.output
    assert 'Traceback' not in out, out
    assert 'sample rate 399.9' in out or 'sample rate 400' in out, out
