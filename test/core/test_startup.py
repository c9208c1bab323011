"""
The budget check from start-up (startup_cases.py's fast part; docs/online.md has the table).

A 3DM-GX3-25 from the independent generator (its window and decimation included) at exactly
its datasheet budget (the worst in-budget unit) and at twice it, fed to the node's pipeline
10 s at a time and checked as the node checks each publication:

* in budget: no ERROR ever, in 16 start-ups of 3 minutes (288 gyro and accelerometer
  axis-publications per term and start-up); WARN on a share of publications no larger than the
  interval level implies.  A term exactly at budget has its 68.3 % interval's lower end above
  the budget 15.9 % of the time; the check rests on the lowest lower end over the open term
  sets and the unresolved terms at their 68.3 % sizes (``FittedModel.alarm_low``), so the
  share is held to <= 15.9 % (measured on 40 start-ups of 5 min: 4.9 % for white noise; it was
  18-20 % with the averaged interval's lower end);
* twice the budget: white noise flagged on every axis from the first publication (10 s) and
  for good (the bias instability, mostly unresolved in 3 minutes, is flagged where it is
  resolved: docs/online.md gives its times).
"""

from core import startup_cases as sc
import numpy as np
import pytest

SECONDS = 180.0


@pytest.fixture(scope='module')
def in_budget():
    return sc.run(16, 1.0, SECONDS, seed=300)


@pytest.fixture(scope='module')
def over_budget():
    return sc.run(6, 2.0, SECONDS, seed=400)


def test_an_in_budget_unit_never_raises_an_error(in_budget):
    summary = sc.summary(in_budget)
    for term, s in summary.items():
        assert s['publications'] == 16 * 6 * int(SECONDS / sc.PUBLISH_S), term
        assert s['error'] == 0, (term, s)
        assert s['warn_share'] <= 0.159, (term, s)


def test_twice_the_budget_is_flagged_from_the_first_publication(over_budget):
    for kind in ('gyro', 'accel'):
        first, stays = sc.time_to_flag(over_budget, 'white_noise', kind)
        assert np.all(first == sc.PUBLISH_S), (kind, first)
        assert np.all(stays == sc.PUBLISH_S), (kind, stays)
