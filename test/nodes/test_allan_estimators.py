"""
The built ``allan`` node over real DDS with ``estimators``: live MDEV and OHDEV (issue 22).

This process streams 6,000 simulated 100 Hz samples (RELIABLE, about 20x real time) to the node
started with ``estimators:=oadev,mdev,ohdev`` (a comma list), the gate off and stride_base
1000 (so every reported factor is formed from every term), and decodes
``imu/allan_deviation/mdev`` and ``.../ohdev`` by their layout.  They must equal the offline
pipeline on the same samples (1e-9; they come out bit-identical), the package's batch
``deviation(kind=...)`` and allantools' ``mdev`` and ``ohdev`` of the whole record (1e-9; the
latter an implementation not ours).  Then
the parameter is changed at run time: an unknown kind is refused with the reason, a string
array without mdev is taken and the mdev topic loses its publisher.
"""

import subprocess

from conftest import DOMAIN, executable, ros_env, spin_until
from imu_allan import deviation
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.live.session import pipeline_options
from imu_allan.core.units import AXES
from imu_allan.formats.imu_adapter import imus_to_arrays
from imu_allan.nodes.allan_parameters import _DEFAULTS
from imu_allan.report.coeffs_layout import decode_deviation
from nodes.allan_feed import AllanFeed, RATE
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

N = 6000
PARAMS = ('estimators:=oadev,mdev,ohdev', 'gate:=false', 'stride_base:=1000')


@pytest.mark.slow
def test_allan_node_publishes_mdev_and_ohdev(ros_context):
    """imu/allan_deviation/<kind>: the node == offline pipeline == allantools on the record."""
    allantools = pytest.importorskip('allantools')
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from std_msgs.msg import Float64MultiArray

    with AllanFeed(ros_context, DOMAIN, n=N, seed=8, params=PARAMS) as run:
        node = run.node
        got = {kind: [] for kind in ('oadev', 'mdev', 'ohdev')}
        for kind in got:
            topic = 'imu/allan_deviation' + ('' if kind == 'oadev' else f'/{kind}')
            node.create_subscription(Float64MultiArray, topic,
                                     lambda m, k=kind: got[k].append(m), 10)
        assert run.spin_until(lambda: node.count_publishers('imu/allan_deviation/mdev') == 1
                              and node.count_publishers('imu/allan_deviation/ohdev') == 1, 40)
        run.spin_until(lambda: all(got.values()), 10)  # discovery of the subscriptions
        run.feed()
        # The cycle that reported every sample may have frozen its sums earlier; the second
        # publication after it started later.
        for values in got.values():
            values.clear()
        assert run.spin_until(lambda: all(len(v) >= 2 for v in got.values()), 60), \
            {k: len(v) for k, v in got.items()}

        t_seen, data_seen = imus_to_arrays(run.msgs)
        params = dict(_DEFAULTS, estimators='oadev,mdev,ohdev', gate=False, stride_base=1000)
        offline = OnlineAllan(axes=AXES, **pipeline_options(params))
        offline.feed(t_seen, data_seen)
        curves = offline.deviations()
        for kind in ('mdev', 'ohdev'):
            tau, dev = decode_deviation(got[kind][-1], topic=f'imu/allan_deviation/{kind}')
            curve = curves[kind]
            np.testing.assert_allclose(tau, curve.tau, rtol=1e-12)
            assert tau[0] == pytest.approx(1 / RATE) and 20 < tau.size
            assert tau[-1] * RATE <= N / 10  # min_clusters (10) x tau within the record
            np.testing.assert_allclose(dev, curve.dev, rtol=1e-9)
            batch = deviation(data_seen, RATE, kind=kind, taus=tau)  # the package's own
            np.testing.assert_array_equal(batch.m, curve.m)
            np.testing.assert_allclose(dev, batch.dev, rtol=1e-9)
            fn = getattr(allantools, kind)
            for a in range(6):
                y = data_seen[:, a] - data_seen[:, a].mean()
                _, ref, _, _ = fn(y, rate=RATE, data_type='freq', taus=tau)
                np.testing.assert_allclose(dev[:, a], ref, rtol=1e-9)
        # The OADEV topic keeps its contract layout.  MDEV is another curve: below OADEV
        # where white noise dominates (MVAR / AVAR -> 1/2 for white rate noise; 0.05-1 s).
        tau_o, adev = decode_deviation(got['oadev'][-1])
        np.testing.assert_array_equal(tau_o, tau)
        mid = (tau >= 0.05) & (tau <= 1.0)
        assert (decode_deviation(got['mdev'][-1])[1][mid] < 0.9 * adev[mid]).all()

        client = node.create_client(SetParameters, '/allan/set_parameters')
        assert client.wait_for_service(timeout_sec=30)

        def set_estimators(value):
            request = SetParameters.Request()
            pv = (ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
                  if isinstance(value, str) else
                  ParameterValue(type=ParameterType.PARAMETER_STRING_ARRAY,
                                 string_array_value=value))
            request.parameters = [Parameter(name='estimators', value=pv)]
            future = client.call_async(request)
            assert spin_until(run.executor, future.done, 30)
            return future.result().results[0]

        refused = set_estimators('oadev,totdev')
        assert not refused.successful and 'unknown estimator(s) totdev' in refused.reason
        # Each accepted change restarts the estimate, also in the middle of a publish cycle
        # (0.5 s period): that cycle is dropped (it once finished on the new, rate-less
        # pipeline: a traceback); four changes make hitting a running cycle likely.
        for value in (['oadev', 'ohdev'], 'mdev,ohdev', ['ohdev'], ['oadev', 'ohdev']):
            assert set_estimators(value).successful
            run.spin_until(lambda: False, 0.3)
        assert run.spin_until(lambda: node.count_publishers('imu/allan_deviation/mdev') == 0,
                              30)
        assert node.count_publishers('imu/allan_deviation/ohdev') == 1
    assert 'Traceback' not in run.output, run.output


def test_allan_unknown_estimator_one_line_exit_2():
    """An unknown kind at start: one line naming the parameter and the kind, exit status 2."""
    out = subprocess.run([executable('allan'), '--ros-args', '-p', 'estimators:=oadev,bogus'],
                         capture_output=True, text=True, timeout=60, env=ros_env(DOMAIN))
    assert out.returncode == 2
    assert 'Traceback' not in out.stderr
    assert 'estimators: unknown estimator(s) bogus' in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
