"""
The fast part of the calibration table (docs/method.md section 11): 10 s to 5 min, both paths.

live_calibration.py's units (nine physical IMUs, with and without a device's window, LSB and
line) from the independent generator, three six-axis records per unit and device setting and
length (270 axes a length), analysed offline (``analyze``'s pipeline) and online (the node's
pipeline fed as the stream grows).  The goals of issue 35, with the tolerance that makes them
fair on this sample (fixed seeds):

* spurious-term axes <= 2 % at each length (measured 0-1.1 % on 360 axes; 2 % of 270 is 5
  axes: a true rate of 1 % exceeds it with probability 2 %);
* over all reported terms of the four lengths (about 1 100 cases) the 68.3 % intervals hold
  the truth 62-75 % of the time (the standard error is 1.4 points: the band is more than four
  of them either side) and the 95 % intervals >= 91 % (standard error 0.7 points);
* every true term not reported lies below its 95 % upper limit >= 90 % of the time.

The whole table, to 24 h, is ``python test/core/live_calibration.py 4 [--online]``.
"""

from core import live_calibration as lc
import numpy as np
import pytest

LENGTHS = (10.0, 30.0, 60.0, 300.0)


@pytest.fixture(scope='module', params=[False, True], ids=['offline', 'online'])
def table(request):
    return lc.summary(lc.run(LENGTHS, groups=3, seed=21, online=request.param))


def test_short_records_report_no_term_the_unit_lacks(table):
    for length, s in table.items():
        assert s['axes'] >= 250, (length, s['axes'])
        assert s['spurious'] / s['axes'] <= 0.02, (length, s['spurious'], s['axes'])


def test_reported_intervals_hold_the_truth_at_their_rate(table):
    cases = sum(s['pooled'][0] for s in table.values())
    c68 = sum(s['pooled'][0] * s['pooled'][1] for s in table.values()) / cases
    c95 = sum(s['pooled'][0] * s['pooled'][2] for s in table.values()) / cases
    assert cases > 1000, cases
    assert 0.62 <= c68 <= 0.75, (c68, c95, cases)
    assert c95 >= 0.91, (c68, c95, cases)


def test_upper_limits_hold_the_terms_not_reported(table):
    flags = [(n, c) for s in table.values() for n, c in s['limit'].values()]
    held = sum(n * c for n, c in flags) / sum(n for n, _ in flags)
    assert held >= 0.90, held
    assert np.isfinite(held)
