"""Health model: noise budget file, budget levels, stamp checks and stream health."""

import math

from imu_allan.core.live import health as hm
from imu_allan.core.units import AXES, DEG, HOUR, IEEE_TERMS, STANDARD_GRAVITY
from imu_allan.errors import InputError
import numpy as np
import pytest


def test_packaged_budget_is_the_datasheet_in_si():
    """0.03 deg/s/sqrt(Hz), 18 deg/h, 80 ug/sqrt(Hz), 0.04 mg converted to SI (1e-6 rel)."""
    budget = hm.NoiseBudget.from_yaml()
    expected = {'white_noise': (0.03 * DEG, 80e-6 * STANDARD_GRAVITY),
                'bias_instability': (18.0 * DEG / HOUR, 0.04e-3 * STANDARD_GRAVITY)}
    for axis in AXES:
        for term, (gyro, accel) in expected.items():
            want = gyro if axis.startswith('gyro') else accel
            assert budget.limit(axis, term) == pytest.approx(want, rel=1e-6)
    assert (budget.warn_ratio, budget.error_ratio) == (1.0, 2.0)


def _table(value, lo, hi, term='white_noise'):
    table = np.full((6, 5, 3), np.nan)
    table[:, IEEE_TERMS.index(term)] = (value, lo, hi)
    return table


def test_budget_levels_follow_the_interval():
    """OK while the interval reaches the budget; WARN above it; ERROR above twice; STALE."""
    budget = hm.NoiseBudget.from_dict({'gyro': {'white_noise': 1.0},
                                       'accel': {'white_noise': 1.0}})
    cases = [((1.2, 0.9, 1.5), hm.OK),     # consistent with the budget
             ((1.3, 1.1, 1.5), hm.WARN),   # whole interval above
             ((2.5, 2.1, 2.9), hm.ERROR),  # whole interval above 2x
             ((1.0, math.nan, math.nan), hm.OK)]
    for (v, lo, hi), level in cases:
        records = hm.budget_health(_table(v, lo, hi), budget)
        assert [r.level for r in records] == [level] * 6, (v, lo, hi)
    rec = hm.budget_health(_table(2.5, 2.1, 2.9), budget)[0]
    assert rec.values['white_noise.budget'] == 1.0
    assert rec.values['white_noise.ci_low'] == 2.1
    assert 'exceeds budget' in rec.message
    assert [r.level for r in hm.budget_health(None, budget)] == [hm.STALE] * 6
    # A term that was not detected does not raise the level.
    assert hm.budget_health(_table(5.0, 4.0, 6.0, 'rate_ramp'), budget)[0].level == hm.OK


@pytest.mark.parametrize('text, problem', [
    ('gyro: {white_noise: -1}', 'must be a positive number'),
    ('gyro: {wite_noise: 1.0}', "unknown or unbudgetable term 'wite_noise'"),
    ('axes: {gyro_w: {white_noise: 1.0}}', "unknown axis 'gyro_w'"),
    ('warn_ratio: 3\nerror_ratio: 2\ngyro: {white_noise: 1}', 'error_ratio must be >='),
    ('[1, 2', 'not valid YAML'),
])
def test_bad_budget_files_name_file_and_problem(tmp_path, text, problem):
    """Each problem is one line: the file, then what is wrong."""
    path = tmp_path / 'budget.yaml'
    path.write_text(text)
    with pytest.raises(InputError) as info:
        hm.NoiseBudget.from_yaml(path)
    assert str(info.value).startswith(f'{path}: ') and problem in str(info.value)
    assert '\n' not in str(info.value)


def test_stamp_monitor_gaps_order_rate():
    """Dropped out-of-order stamps, gaps flagged before the sample after them, rate."""
    mon = hm.StampMonitor(100.0)
    t = np.arange(0, 10, 0.01)
    t = np.concatenate([t[:500], [4.0, 4.99], t[500:700], t[710:]])  # 2 late, 1 gap of 0.11 s
    keep, brk = mon.check(t[:300])
    keep2, brk2 = mon.check(t[300:])
    keep, brk = np.concatenate([keep, keep2]), np.concatenate([brk, brk2])
    assert mon.out_of_order == 2 and (~keep).sum() == 2
    assert mon.gaps == 1 and brk.sum() == 1
    assert t[np.flatnonzero(brk)[0]] == pytest.approx(7.10)
    assert mon.max_gap_s == pytest.approx(0.11)
    assert mon.measured_rate() == pytest.approx(989 / 9.99, rel=1e-9)


def test_stream_health_levels():
    """STALE before data, OK when regular, WARN on a wrong rate, ERROR when silent."""
    mon = hm.StampMonitor(100.0)
    assert hm.stream_health(mon, mon.take_recent(), math.inf).level == hm.STALE
    mon.check(np.arange(0, 5, 0.01))
    rec = hm.stream_health(mon, mon.take_recent(), 0.1)
    assert rec.level == hm.OK, rec.message
    mon.check(5 + np.arange(0, 5, 1 / 80.0))
    rec = hm.stream_health(mon, mon.take_recent(), 0.1)
    assert rec.level == hm.WARN and 'rate 80' in rec.message
    assert hm.stream_health(mon, mon.take_recent(), 5.0).level == hm.ERROR
    rec = hm.stream_health(mon, mon.take_recent(), 0.1, excluded_share=0.8)
    assert rec.level == hm.WARN and '80 % of samples excluded' in rec.message
