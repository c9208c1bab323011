"""
The online pipeline (the allan node's) under NaN, inf and non-physical samples.

Such values are rejected per axis before the gate and the estimator, counted per axis, and
reported by ``stream_health`` as WARN with the counts.  A rejected value leaves out its own
axis only: that axis's phase restarts there (as at a stamp gap), the other axes keep the sample
and give exactly the numbers of the clean record; the gate never sees the bad value, so it is
never taken for motion.  20,000 samples at 100 Hz with fixed seeds: a few seconds.
"""

import warnings

from core.segment_cases import pooled_batch, split_segments
from imu_allan.core.live import health as hm
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.units import AXES
import numpy as np
import pytest

RATE = 100.0
N = 20_000
WHITE = 1e-3  # rad/s or m/s^2 per sample


def _record(seed=0):
    rng = np.random.default_rng(seed)
    data = rng.normal(0.0, WHITE, (N, 6))
    data[:, 5] += 9.81
    return np.arange(N) / RATE, data


def _run(t, data, batch=250):
    """Feed in batches: an int, or a seed for random batch sizes (1-600)."""
    pipe = OnlineAllan(RATE, max_tau=20.0)
    if isinstance(batch, int):
        sizes = [batch] * (N // batch + 1)
    else:
        sizes = np.random.default_rng(batch[0]).integers(1, 600, N)
    i = 0
    for size in sizes:
        if i >= N:
            break
        pipe.feed(t[i:i + size], data[i:i + size])
        i += size
    return pipe


def _strict(t, data, batch=250):
    """Run with every warning an error (no RuntimeWarning may escape)."""
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        pipe = _run(t, data, batch)
        return pipe, pipe.result()


def _assert_same(result, clean, columns):
    for name in ('avar', 'adev', 'edf', 'ci_low', 'ci_high'):
        np.testing.assert_array_equal(getattr(result, name)[:, columns],
                                      getattr(clean, name)[:, columns])


@pytest.mark.parametrize('bad', [np.nan, np.inf, -1e300, 2e3])
def test_every_50th_gyro_x_bad(bad):
    """
    Every 50th gyro_x bad: counted; gyro_x kept at the averaging times 49 samples allow.

    The five other axes are bit-identical to the clean record; nothing is excluded as motion;
    gyro_x is finite up to m = 24 (49-sample segments) and NaN beyond, and its white noise
    is within 5 % of the truth (about 19,600 samples: a 1 % standard error at m = 1).
    """
    t, data = _record()
    clean_pipe = _run(t, data)
    clean = clean_pipe.result()
    data[::50, 0] = bad
    pipe, result = _strict(t, data)
    assert pipe.rejected_total.tolist() == [N // 50, 0, 0, 0, 0, 0]
    assert pipe.gate.n_excluded == clean_pipe.gate.n_excluded == 0
    assert pipe.excluded_share == 0.0
    np.testing.assert_array_equal(result.m, clean.m)
    _assert_same(result, clean, [1, 2, 3, 4, 5])
    short = result.m <= 24
    assert np.isfinite(result.adev[short, 0]).all() and np.isnan(result.adev[~short, 0]).all()
    j = int(np.argmin(np.abs(result.tau - 0.1)))
    assert result.adev[j, 0] == pytest.approx(clean.adev[j, 0], rel=0.05)
    fitted = pipe.fit(result)
    n_true = WHITE / np.sqrt(RATE)  # continuous-time white noise of the simulated samples
    assert fitted.value('gyro_x', 'white_noise') == pytest.approx(n_true, rel=0.05)
    assert fitted.value('gyro_y', 'white_noise') == pytest.approx(
        clean_pipe.fit(clean).value('gyro_y', 'white_noise'), rel=1e-12)
    assert pipe.take_rejected() == {'gyro_x': N // 50} and pipe.take_rejected() == {}


def test_random_bad_values_per_axis_pooled_and_chunk_invariant():
    """
    NaN, inf, 1e300 and 2e4 at seeded random positions in gyro_x and accel_y.

    Those two axes equal the batch estimator applied to each of their own segments (the
    record split at their bad samples) and pooled, to 1e-10 relative (rounding), at every
    factor tracked at stride 1; where an axis's segments are too short for a factor it is NaN
    there.  The other axes are
    bit-identical to the clean record.  Two random batchings give bit-identical results.
    """
    t, data = _record(3)
    clean_pipe = _run(t, data)
    clean = clean_pipe.result()
    rng = np.random.default_rng(4)
    bad = np.zeros(data.shape, bool)
    bad[rng.choice(N, 300, replace=False), 0] = True
    bad[rng.choice(N, 7, replace=False), 4] = True
    dirty = data.copy()
    dirty[bad] = rng.choice([np.nan, np.inf, -np.inf, 1e300, 2e4], bad.sum())
    pipe, result = _strict(t, dirty, batch=(5,))
    again, result2 = _strict(t, dirty, batch=(6,))
    for name in ('avar', 'edf', 'ci_low', 'ci_high'):
        np.testing.assert_array_equal(getattr(result, name), getattr(result2, name))
    assert pipe.rejected_total.tolist() == bad.sum(axis=0).tolist() == [300, 0, 0, 0, 7, 0]
    assert pipe.gate.n_excluded == 0
    np.testing.assert_array_equal(result.m, clean.m)
    _assert_same(result, clean, [1, 2, 3, 5])
    n_in = pipe.estimator.n_offered  # the gate still holds the last one or two windows
    assert n_in == clean_pipe.estimator.n_offered > N - 50
    np.testing.assert_array_equal(pipe.estimator.n_used_axes, n_in - bad[:n_in].sum(axis=0))
    assert pipe.estimator.n_used == n_in
    for a in (0, 4):
        pooled, count = pooled_batch(split_segments(data[:n_in, a], bad[:n_in, a]), result.m,
                                     RATE)
        enough = count + 2 * result.m - 1 >= pipe.estimator.min_clusters * result.m
        np.testing.assert_array_equal(np.isnan(result.avar[:, a]), ~enough)
        # Factors above stride_base use 1 term in `stride` (docs/online.md): exact below.
        exact = result.m <= 256
        np.testing.assert_allclose(result.avar[exact, a], np.where(enough, pooled, np.nan)[exact],
                                   rtol=1e-10)
    assert np.isnan(result.avar[-1, 0]) and np.isfinite(result.avar[exact, 4]).all()


def test_leading_and_long_bad_runs_and_a_bad_axis_throughout():
    """
    Bad values before any good one, a 3 s run of them, an axis bad throughout.

    No warning; nothing excluded as motion (the gate sees the axis's last good value in
    their place); the untouched axes equal the clean record exactly.  The leading run is
    shorter than one gate window (0.2 s): see docs/online.md for a longer one.
    """
    t, data = _record(2)
    clean = _run(t, data).result()
    data[:10, 1] = np.nan
    data[5000:5300, 1] = -np.inf
    data[:, 3] = np.inf
    pipe, result = _strict(t, data)
    assert pipe.rejected_total.tolist() == [0, 310, 0, N, 0, 0]
    assert pipe.gate.n_excluded == 0
    np.testing.assert_array_equal(result.m, clean.m)
    _assert_same(result, clean, [0, 2, 4, 5])
    assert np.isnan(result.avar[:, 3]).all() and np.isfinite(result.avar[:, 1]).all()
    assert pipe.estimator.n_used_axes[3] == 0


def test_stream_health_warns_with_the_counts():
    """The diagnostic names the axes and counts; without rejections it stays OK."""
    t, data = _record(1)
    data[100, 3] = np.nan
    data[200:203, 1] = 1e300
    pipe = _run(t, data)
    rec = pipe.stream_health(0.0)
    assert rec.level == hm.WARN and 'gyro_y 3' in rec.message and 'accel_x 1' in rec.message
    assert 'motion' not in rec.message
    assert rec.values['rejected_recent.gyro_y'] == 3
    assert rec.values['rejected_total.gyro_y'] == 3
    calm = pipe.stream_health(0.0)
    assert calm.level == hm.OK, calm.message
    assert calm.values['rejected_total.accel_x'] == 1  # the totals stay in the values
    assert set(AXES) >= {k.split('.')[1] for k in rec.values if k.startswith('rejected')}


def test_damaged_stamps_left_out_and_counted():
    """
    Samples with a NaN stamp (a nanosecond field >= 1e9 decodes so) are left out alone.

    Before this rule one NaN stamp poisoned the stream monitor's running maximum, and every
    later sample was dropped as out of order.  The samples around them still count: the
    result equals the record without those samples, and the count is in the stream status.
    """
    t, data = _record(4)
    bad = np.random.default_rng(5).choice(np.arange(100, N), 7, replace=False)
    t_bad = t.copy()
    t_bad[bad] = np.nan
    keep = np.isfinite(t_bad)
    pipe, result = _strict(t_bad, data)
    assert pipe.bad_stamps == 7
    assert pipe.monitor.n_kept == N - 7
    ref = OnlineAllan(RATE, max_tau=20.0)
    ref.feed(t[keep], data[keep])
    assert np.allclose(result.avar, ref.result().avar, rtol=1e-12, atol=0.0)
    assert pipe.stream_health(0.0).values['bad_stamps'] == 7
