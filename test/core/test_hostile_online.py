"""
The online pipeline (the allan node's) under NaN, inf and non-physical samples.

Such values are rejected before the gate and the estimator, counted per axis, and reported by
``stream_health`` as WARN with the counts; the estimate stays finite and no numpy warning
escapes.  20,000 samples at 100 Hz with fixed seeds: about a second.
"""

import warnings

from imu_allan.core import health as hm
from imu_allan.core.online import OnlineAllan
from imu_allan.core.units import AXES
import numpy as np
import pytest

RATE = 100.0
N = 20_000


def _record(seed=0):
    rng = np.random.default_rng(seed)
    data = rng.normal(0.0, 1e-3, (N, 6))
    data[:, 5] += 9.81
    return np.arange(N) / RATE, data


def _run(t, data, batch=250):
    pipe = OnlineAllan(RATE, max_tau=20.0)
    for i in range(0, N, batch):
        pipe.feed(t[i:i + batch], data[i:i + batch])
    return pipe


@pytest.mark.parametrize('bad', [np.nan, np.inf, -1e300, 2e3])
def test_bad_values_rejected_counted_and_estimate_kept(bad):
    """Every 50th gyro_x sample bad: counted, the rest analysed, no RuntimeWarning."""
    t, data = _record()
    clean = _run(t, data).result()
    data[::50, 0] = bad
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        pipe = _run(t, data)
        result = pipe.result()
    assert pipe.rejected_total.tolist() == [N // 50, 0, 0, 0, 0, 0]
    assert np.isfinite(result.adev).all()
    # 2 % of the samples left out as gaps: the white-noise level is unchanged within 5 %
    # (the 1-s deviation has thousands of degrees of freedom here).
    j = int(np.argmin(np.abs(result.tau - 1.0)))
    assert result.adev[j, 0] == pytest.approx(clean.adev[j, 0], rel=0.05)
    assert pipe.take_rejected() == {'gyro_x': N // 50} and pipe.take_rejected() == {}


def test_stream_health_warns_with_the_counts():
    """The diagnostic names the axes and counts; without rejections it stays OK."""
    t, data = _record(1)
    data[100, 3] = np.nan
    data[200:203, 1] = 1e300
    pipe = _run(t, data)
    rec = hm.stream_health(pipe.monitor, pipe.monitor.take_recent(), 0.0,
                           rejected=pipe.take_rejected())
    assert rec.level == hm.WARN and 'gyro_y 3' in rec.message and 'accel_x 1' in rec.message
    calm = hm.stream_health(pipe.monitor, pipe.monitor.take_recent(), 0.0,
                            rejected=pipe.take_rejected())
    assert calm.level == hm.OK, calm.message
    assert set(AXES) >= {k.split('.')[1] for k in rec.values if k.startswith('rejected')}
