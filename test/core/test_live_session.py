"""
The allan node's computation without ROS: :class:`LiveSession` and its ``/diagnostics`` words.

One minute of a simulated 3DM-GX3-25 (the package's thesis model) fed in 10-s blocks: a publish
cycle run in short steps gives a Publication whose table equals the pipeline's own fit of the
same samples; the advice follows on the next steps; the records name every part the node
publishes, and a term the record does not resolve raises no budget level.
"""

import math

from imu_allan.core.live import health as hm
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.live.session import LiveSession, pipeline_options
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
from imu_allan.nodes.allan_parameters import _DEFAULTS
from imu_allan.report.coeffs_layout import coefficient_table, limit_values
from imu_allan.report.live_status import session_records
import numpy as np
import pytest

RATE = 100.0


@pytest.fixture(scope='module')
def run():
    params = dict(_DEFAULTS, rate_hz=RATE, advice_period=0.0)
    data = simulate(thesis_gx3_25_model(), 6000, RATE, seed=4)
    data[:, 5] += 9.80665
    t = np.arange(data.shape[0]) / RATE
    logs = []
    session = LiveSession(params, lambda level, text: logs.append((level, text)))
    for k in range(0, 6000, 1000):
        session.feed(t[k:k + 1000], data[k:k + 1000])
    assert session.start_cycle() and not session.start_cycle()  # one cycle at a time
    # no step runs without budget: a drain with no time left does no work
    idle = session.advance(0.0)
    assert idle is None and session.busy
    pub = None
    while pub is None:
        pub = session.advance(0.001)  # a step or a few per call, as between drains
    while session.busy:  # the advice's steps
        session.advance(0.01)
    reference = OnlineAllan(axes=session.pipeline.axes, **pipeline_options(params))
    reference.feed(t, data)
    return session, pub, reference.fit(reference.result()), logs


def test_a_cycle_in_steps_publishes_the_pipelines_own_fit(run):
    session, pub, reference, _ = run
    np.testing.assert_allclose(coefficient_table(pub.fitted), coefficient_table(reference),
                               rtol=1e-12, equal_nan=True)
    # the upper limits were computed in the cycle's steps, not left to the publishing callback
    for axis in session.pipeline.axes:
        assert set(pub.fitted.fits[axis].upper_limits) == set(pub.fitted.limits(axis)), axis
    np.testing.assert_allclose(limit_values(pub.fitted), limit_values(reference), rtol=1e-12,
                               equal_nan=True)
    n = np.array([pub.fitted.value(a, 'white_noise') for a in session.pipeline.axes])
    np.testing.assert_allclose(pub.variance, n ** 2 * RATE)  # N^2 f, robot_localization's


def test_records_name_every_part_and_unresolved_terms_raise_nothing(run):
    session, pub, _, _ = run
    records = session_records(session, 0.1, 'allan: ')
    names = {r.name for r in records}
    assert {'allan: IMU stream', 'allan: recording advice', 'allan: gyro_x noise',
            'allan: gyro_x model', 'allan: gyro_x advice'} <= names
    for rec in records:
        if rec.name.endswith(' noise'):
            for term in ('white_noise', 'bias_instability'):
                if not math.isfinite(rec.values[term]):  # not resolved: a limit, no level
                    assert rec.level == hm.OK or term not in rec.message, rec.message
    advice = next(r for r in records if r.name == 'allan: recording advice')
    assert advice.level in (hm.OK, hm.WARN) and advice.message  # not STALE: it ran


def test_the_advice_follows_a_record_that_doubled_within_its_period():
    """With advice_period an hour: advice at 10 s, again at 20 s (doubled), not at 30 s."""
    params = dict(_DEFAULTS, rate_hz=RATE, advice_period=3600.0)
    data = simulate(thesis_gx3_25_model(), 3000, RATE, seed=5)
    t = np.arange(data.shape[0]) / RATE
    session = LiveSession(params, lambda level, text: None)
    seen = []
    for k in range(0, 3000, 1000):
        session.feed(t[k:k + 1000], data[k:k + 1000])
        assert session.start_cycle()
        while session.busy:
            session.advance(0.01)
        seen.append(session.advice.duration_s)
    # (the record is the samples used: the gate's first 0.2 s are not)
    assert seen[1] >= 2 * seen[0] - 0.5 and seen[2] == seen[1], seen
