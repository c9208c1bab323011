"""The built ``denoise`` executable over real DDS: same numbers as the core, original stamps."""

import math
import subprocess

from conftest import DOMAIN, executable, NodeRun, ros_env, spin_until
from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.live.health import RateFinder
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.imu_adapter import imus_to_arrays
from imu_allan.nodes.denoise import _DEFAULTS, make_denoiser
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

RATE = 100.0
N = 6000


@pytest.mark.slow
def test_denoise_node_stream(ros_context):
    """
    60 s of thesis-model data through the node equal the offline BlockDenoiser.

    Every output equals the core with the same settings (1e-12: rounding only), stamps are the
    originals in order, the latency bound holds, and the short-tau ADEV drops (sym8 level 4
    removes the band above fs/32: at tau0 the white-noise ADEV falls by far more than 4x).
    """
    from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
    from sensor_msgs.msg import Imu

    data = simulate(thesis_gx3_25_model(), N, RATE, seed=17)
    data[:, 5] += 9.80665
    msgs = []
    for i, row in enumerate(data):
        msg = Imu()
        ti = 1_700_000_000.0 + i / RATE
        msg.header.stamp.sec = int(math.floor(ti))
        msg.header.stamp.nanosec = int(round((ti - math.floor(ti)) * 1e9))
        msg.header.frame_id = 'imu_link'
        msg.orientation_covariance[0] = -1.0
        w, a = msg.angular_velocity, msg.linear_acceleration
        w.x, w.y, w.z, a.x, a.y, a.z = (float(v) for v in row)
        msgs.append(msg)
    t_in, data_in = imus_to_arrays(msgs)

    cmd = [executable('denoise'), '--ros-args', '-p', 'queue_depth:=20000',
           '-p', 'qos_overrides./imu/data_raw.subscription.reliability:=reliable',
           '-p', 'qos_overrides./imu/data_denoised.publisher.reliability:=reliable',
           '-p', 'qos_overrides./imu/data_denoised.publisher.depth:=20000']
    with NodeRun(cmd, ros_context, 'denoise_test_client') as run:
        node, executor = run.node, run.executor
        received = []
        qos = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=20000,
                         reliability=QoSReliabilityPolicy.RELIABLE)
        node.create_subscription(Imu, 'imu/data_denoised', received.append, qos)
        pub = node.create_publisher(Imu, 'imu/data_raw', qos)
        assert spin_until(executor, lambda: pub.get_subscription_count() > 0, 30)
        assert spin_until(executor, lambda: node.count_publishers('imu/data_denoised') > 0,
                          30)
        for i in range(0, N, 500):
            for msg in msgs[i:i + 500]:
                pub.publish(msg)
            executor.spin_once(timeout_sec=0.01)
        # rate_hz defaults to 0: the node measures it from the stamps, as RateFinder does
        rate = RateFinder().add(t_in, data_in)
        reference = make_denoiser(dict(_DEFAULTS, rate_hz=rate))
        expected = reference.push(data_in)
        assert spin_until(executor, lambda: len(received) >= expected.shape[0], 60), \
            f'{len(received)} of {expected.shape[0]} denoised messages'
        spin_until(executor, lambda: False, 0.5)  # nothing more may come
    out = run.output
    assert 'Traceback' not in out, out
    assert len(received) == expected.shape[0]
    assert expected.shape[0] >= N - reference.latency_samples
    t_out, data_out = imus_to_arrays(received)
    np.testing.assert_array_equal(t_out, t_in[:len(received)])
    np.testing.assert_allclose(data_out, expected, rtol=0, atol=1e-12)
    assert all(m.header.frame_id == 'imu_link' for m in received)
    before = allan_deviation(data_in[:len(received)], RATE, taus=[0.01])
    after = allan_deviation(data_out, RATE, taus=[0.01])
    assert np.all(before.adev[0] / after.adev[0] > 4.0)
    assert 'latency up to 255 samples' in out


def test_denoise_bad_parameter_one_line_exit_2():
    """An unknown wavelet: one line naming the parameter, exit status 2."""
    out = subprocess.run([executable('denoise'), '--ros-args', '-p', 'wavelet:=sym99'],
                         capture_output=True, text=True, timeout=60, env=ros_env(DOMAIN))
    assert out.returncode == 2
    assert out.stderr.strip() == ("denoise: wavelet: unknown discrete wavelet 'sym99' "
                                  '(e.g. haar, db4, sym8)')


def test_denoise_help_without_ros():
    """``denoise --help`` answers without ROS and states the latency rule."""
    out = subprocess.run([executable('denoise'), '--help'], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0
    for name in ('wavelet', 'level', 'rule', 'noise_source', 'median_window', 'latency'):
        assert name in out.stdout
