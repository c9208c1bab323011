"""
The built ``allan`` executable over real DDS: coefficients, exactness and diagnostics.

A publisher in this process streams 300 s of simulated 100 Hz IMU data (about 20x faster than
real time, stamps 10 ms apart) to the node; a subscriber decodes ``imu/allan_coeffs`` by its
layout.  RELIABLE QoS (through the node's QoS override parameters) so that no sample is lost and
the node's numbers can be compared with the offline path on exactly the same samples.
"""

import math
import subprocess
import time

from conftest import DOMAIN, executable, ros_env, spin_until
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.live.session import pipeline_options
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.units import AXES, IEEE_TERMS
from imu_allan.nodes.allan_parameters import _DEFAULTS
from imu_allan.report.coeffs_layout import coefficient_table, decode_adequacy
from nodes.allan_feed import AllanClient, imu_messages
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

RATE = 100.0
N = 30000
# Bias instability large enough that its flat Allan region (from about 1 s) is inside the
# 30 s the 300 s record can resolve, so the fit has two terms to find per axis.
MODEL = NoiseModel.from_dict({
    'gyro': {'white_noise': 5.0e-4, 'bias_instability': 8.0e-4},
    'accel': {'white_noise': 8.0e-4, 'bias_instability': 1.5e-3}})
LOOSE = 'gyro: {white_noise: 5.0e-3, bias_instability: 8.0e-3}\n' \
        'accel: {white_noise: 8.0e-3, bias_instability: 1.5e-2}\n'
TIGHT = 'gyro: {white_noise: 5.0e-5, bias_instability: 8.0e-5}\n' \
        'accel: {white_noise: 8.0e-5, bias_instability: 1.5e-4}\n'


def _decode_coeffs(msg):
    """Decode imu/allan_coeffs strictly by its layout (labels, sizes, strides, offset)."""
    dims = msg.layout.dim
    assert [d.label for d in dims] == ['axis', 'term', 'stat']
    assert [d.size for d in dims] == [6, 5, 3]
    assert [d.stride for d in dims] == [90, 15, 3]
    assert msg.layout.data_offset == 0
    return np.asarray(msg.data[:90], dtype=float).reshape(6, 5, 3)


@pytest.mark.slow
def test_allan_node_end_to_end(ros_context, tmp_path):
    """True coefficients inside the published intervals; node == offline; budget levels."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    loose, tight = tmp_path / 'loose.yaml', tmp_path / 'tight.yaml'
    loose.write_text(LOOSE)
    tight.write_text(TIGHT)
    data = simulate(MODEL, N, RATE, seed=11)
    data[:, 5] += 9.80665  # gravity on z: the estimator must not care about a constant
    t0 = 1_700_000_000.0
    t = t0 + np.arange(N) / RATE
    msgs = imu_messages(data, t)
    # The msg stamps are what the node sees: decode them back exactly as it does.
    from imu_allan.formats.imu_adapter import imus_to_arrays
    t_seen, data_seen = imus_to_arrays(msgs)

    cmd = [executable('allan'), '--ros-args', '-p', 'publish_period:=1.0',
           '-p', f'budget_file:={loose}', '-p', 'queue_depth:=40000',
           '-p', 'targets:=bias_instability=0.05', '-p', 'advice_period:=2.0',
           '-p', 'qos_overrides./imu/data_raw.subscription.reliability:=reliable']
    with AllanClient(cmd, ros_context, 'allan_test_client', depth=40000) as run:
        node, executor = run.node, run.executor
        diags = run.diags
        run.publish(msgs)

        def status(array, suffix):
            return next(s for s in array.status if s.name.endswith(suffix))

        def values(s):
            return {kv.key: kv.value for kv in s.values}

        seen_complete = run.wait_counted(N)
        table = _decode_coeffs(run.wait_published_after(seen_complete))

        # 1. The node's numbers equal the offline pipeline on the same samples.
        params = dict(_DEFAULTS, budget_file=str(loose))
        offline = OnlineAllan(axes=AXES, **pipeline_options(params))
        offline.feed(t_seen, data_seen)
        expected = coefficient_table(offline.fit(offline.result()), AXES)
        assert np.array_equal(np.isnan(table), np.isnan(expected))
        np.testing.assert_allclose(table, expected, rtol=1e-9, equal_nan=True)

        # 2. True coefficients inside the published intervals.  68.3 % intervals miss about a
        # third of the time, so: every detected true value inside the interval widened to
        # 3 sigma (each side scaled by 3), and at least half inside the published one.
        inside, checked = 0, 0
        for i, axis in enumerate(AXES):
            for term in ('white_noise', 'bias_instability'):
                value, lo, hi = table[i, IEEE_TERMS.index(term)]
                if term == 'white_noise':
                    assert math.isfinite(value), f'{axis}: white noise not detected'
                if not math.isfinite(value):
                    continue
                true = MODEL.value(axis, term)
                assert value - 3 * (value - lo) <= true <= value + 3 * (hi - value), \
                    (axis, term, true, value, lo, hi)
                inside += lo <= true <= hi
                checked += 1
        detected_b = np.isfinite(table[:, IEEE_TERMS.index('bias_instability'), 0]).sum()
        assert detected_b >= 4, f'bias instability detected on {detected_b} of 6 axes'
        assert inside >= checked / 2, f'{inside} of {checked} inside the 68.3 % intervals'

        # 3. Diagnostics: OK against the loose budget, ERROR once it is tightened.
        last = diags[-1][1]
        levels = [status(last, f'{a} noise').level for a in AXES]
        assert levels == [b'\x00'] * 6, [status(last, f'{a} noise').message for a in AXES]
        stream = values(status(last, 'IMU stream'))
        assert stream['gaps_total'] == '0' and stream['out_of_order_total'] == '0'
        # The adequacy of each axis's model (issue 29): the simulated thesis model is what it
        # is fitted with, so every axis's model describes its curve (p >= 0.001: a false
        # WARN is 1 in 1000 per axis), on /diagnostics and after the coefficient table.
        for a in AXES:
            model = status(last, f'{a} model')
            assert model.level == b'\x00', model.message
            assert float(values(model)['p']) >= 1e-3
        assert np.all(decode_adequacy(run.coeffs[-1][1]) >= 1e-3)

        # 3b. The recording advice (issue 12): after 300 s, bias instability to the asked 5 %
        #     needs more recording: WARN with the time, per-term times as key-values.
        #     The advice of the whole record (recorded_s = 300 s): one of an earlier estimate
        #     may name a model the adequacy test rejected there (flicker-dominated short
        #     records: about 1 % per axis, docs/method.md section 10).
        def whole(m):
            a = status(m, 'recording advice')
            return a.level != b'\x03' and float(values(a).get('recorded_s', 0)) >= N / RATE - 1
        assert spin_until(executor, lambda: any(whole(m) for _, m in diags), 30), \
            'no recording advice of the whole record published'
        advice = next(status(m, 'recording advice') for _, m in reversed(diags) if whole(m))
        assert advice.name == 'allan: recording advice'
        kv = values(advice)
        assert advice.level == b'\x01' and advice.message.startswith('record '), advice.message
        assert float(kv['record_more_s']) > 0
        # the same message has each axis's sentence beside it, its numbers as key-values
        axis_advice = next(status(m, 'gyro_x advice') for _, m in reversed(diags) if whole(m))
        akv = values(axis_advice)
        assert float(akv['white_noise.more_s']) == 0.0
        assert float(akv['white_noise.rel_halfwidth']) < 0.02
        assert axis_advice.message.startswith('white noise ±'), axis_advice.message

        client = node.create_client(SetParameters, '/allan/set_parameters')
        assert client.wait_for_service(timeout_sec=10)

        def set_path(name, path):
            request = SetParameters.Request()
            request.parameters = [Parameter(name=name, value=ParameterValue(
                type=ParameterType.PARAMETER_STRING, string_value=str(path)))]
            future = client.call_async(request)
            assert spin_until(executor, future.done, 10)
            return future.result().results[0]

        def set_budget(path):
            return set_path('budget_file', path)

        refused = set_budget(tmp_path / 'missing.yaml')
        assert not refused.successful and 'missing.yaml' in refused.reason
        assert set_budget(tight).successful
        changed = time.monotonic()

        def tightened():
            fresh = [m for when, m in diags if when > changed + 0.01]
            return fresh and all(status(fresh[-1], f'{a} noise').level == b'\x02'
                                 for a in AXES)
        assert spin_until(executor, tightened, 15), 'levels did not change to ERROR'

        # 4. The discrepancy hook: with a model file, /diagnostics carries the gap
        #    per axis and the effect that fits the excess.  The true model is consistent; a
        #    model without bias instability is not, and bias instability is named.
        true_file, white_file = tmp_path / 'true.yaml', tmp_path / 'white.yaml'
        MODEL.to_yaml(true_file)
        NoiseModel({a: {'white_noise': MODEL.terms[a]['white_noise']}
                    for a in AXES}).to_yaml(white_file)

        def discrepancy_after(path):
            assert set_path('model_file', path).successful
            since = time.monotonic()

            def ready():
                fresh = [m for when, m in diags if when > since + 0.01]
                return fresh and any(x.name.endswith('gyro_x model discrepancy')
                                     for x in fresh[-1].status)
            assert spin_until(executor, ready, 15), 'no discrepancy status published'
            last = [m for when, m in diags if when > since + 0.01][-1]
            return [status(last, f'{a} model discrepancy') for a in AXES]

        consistent = discrepancy_after(true_file)
        assert sum(s.level == b'\x00' for s in consistent) >= 5, [s.message for s in consistent]
        assert all(math.isfinite(float(values(s)['gap'])) for s in consistent)
        missing = discrepancy_after(white_file)
        assert all(s.level == b'\x01' for s in missing), [s.message for s in missing]
        named = [values(s)['effect'] for s in missing]
        assert named.count('bias_instability') >= 5, named
        assert all(float(values(s)['gap']) > 2 for s in missing)
    out = run.output
    assert 'Traceback' not in out, out


def test_allan_help_without_ros():
    """``allan --help`` answers without ROS and lists the parameters."""
    out = subprocess.run([executable('allan'), '--help'], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0
    for name in ('publish_period', 'window_s', 'budget_file', 'model_file', 'gate'):
        assert name in out.stdout


@pytest.mark.parametrize('param, words', [('rate_hz:=-5.0', 'rate_hz'),
                                          ('budget_file:=/nonexistent/b.yaml',
                                           '/nonexistent/b.yaml: cannot read budget file'),
                                          ('terms:=white,bias', "unknown term(s) 'white', 'bias'"),
                                          ('targets:=bias_instability=7',
                                           'targets: bias_instability: relative half-width 7 '
                                           'outside')])
def test_allan_bad_parameter_one_line_exit_2(param, words):
    """A bad parameter at start: one line on stderr naming it, exit status 2, no traceback."""
    out = subprocess.run([executable('allan'), '--ros-args', '-p', param], capture_output=True,
                         text=True, timeout=60, env=ros_env(DOMAIN))
    assert out.returncode == 2
    assert 'Traceback' not in out.stderr and words in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
