"""
The built ``allan`` node's change test over real DDS: a stream that changes at a known stamp.

240 s of simulated 100 Hz samples (published about 20x faster than real time, RELIABLE so
that every sample arrives); from stamp T0 + 120 s the gyro_x white noise is 1.5x stronger.
With ``change_window_s`` 20 s (step 5 s) the node must put ``allan: gyro_x change`` at WARN
with ``changed_at`` within one step of the change's stamp and ``what`` white_noise, keep the
other axes OK, and go back to OK after ``ros2 param set`` of ``change_reset``.
"""

import math

from imu_allan.core.simulation.simulate import simulate
from nodes.allan_feed import AllanFeed, imu_messages, MODEL, RATE, status_values
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

N = 24000
T0 = 1_700_000_000.0
CHANGE_AT = T0 + 120.0


def _changed_stream():
    data = simulate(MODEL, N, RATE, seed=31)
    data[:, 5] += 9.80665
    tc = int((CHANGE_AT - T0) * RATE)
    extra = np.random.default_rng(5).standard_normal(N - tc)
    data[tc:, 0] += 5.0e-4 * math.sqrt(RATE) * math.sqrt(1.5 ** 2 - 1.0) * extra
    return imu_messages(data, T0 + np.arange(N) / RATE)


def _change_status(array, axis):
    for status in array.status:
        if status.name.endswith(f'{axis} change'):
            return status
    return None


@pytest.mark.slow
def test_allan_node_reports_a_change_and_resets(ros_context):
    """WARN on gyro_x with the stamp, OK elsewhere; a change_reset set clears it."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    with AllanFeed(ros_context, None, n=N, params=('change_window_s:=20.0',)) as run:
        run.msgs = _changed_stream()
        run.feed()

        def warned():
            return any(_level(_change_status(m, 'gyro_x')) == 1 for _, m in run.diags)
        assert run.spin_until(warned, 60), 'no change WARN on gyro_x'
        last = next(m for _, m in reversed(run.diags) if _change_status(m, 'gyro_x'))
        gx = status_values(last, 'gyro_x change')
        assert gx['what'] == 'white_noise'
        assert abs(float(gx['changed_at']) - CHANGE_AT) <= 5.0 + 1e-6  # one step
        assert 1.3 < float(gx['ratio']) < 1.7
        for axis in ('gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z'):
            assert _level(_change_status(last, axis)) == 0, axis

        client = run.node.create_client(SetParameters, '/allan/set_parameters')
        assert client.wait_for_service(timeout_sec=10)
        request = SetParameters.Request()
        request.parameters = [Parameter(name='change_reset', value=ParameterValue(
            type=ParameterType.PARAMETER_BOOL, bool_value=True))]
        future = client.call_async(request)
        assert run.spin_until(future.done, 10) and future.result().results[0].successful
        n_before = len(run.diags)

        def cleared():
            return any(_level(_change_status(m, 'gyro_x')) == 0
                       for _, m in run.diags[n_before:])
        assert run.spin_until(cleared, 30), 'the reset did not clear the WARN'


def _level(status):
    """Return the level of a status as an int (rclpy gives a byte), -1 when absent."""
    if status is None:
        return -1
    level = status.level
    return level[0] if isinstance(level, bytes) else int(level)
