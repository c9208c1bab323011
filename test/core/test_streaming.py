"""The bounded-memory online Allan estimator against the batch overlapping estimator."""

from core.segment_cases import feed_chunked, pooled_batch, split_segments
from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.live.online import online_allan, OnlineAllan
from imu_allan.core.live.streaming import factor_grid, StreamingAllan
import numpy as np
import pytest

RATE = 100.0


def _reference_sums(x_phase, m, stride=1, k_min=0):
    """Sum of squared second differences over k = k_min.. (multiples of stride) and the count."""
    k = np.arange(0, x_phase.shape[0] - 2 * m, stride)
    k = k[k >= k_min]
    d = x_phase[k + 2 * m] - 2 * x_phase[k + m] + x_phase[k]
    return (d * d).sum(axis=0), k.size


def _phase(data):
    x = np.zeros((data.shape[0] + 1, data.shape[1]))
    x[1:] = np.cumsum(data - data.mean(axis=0), axis=0)
    return x


def test_exact_mode_equals_batch_estimator(record):
    """
    exact=True: every tracked factor equals allan_deviation(..., taus=...) to 1e-10.

    Any difference beyond float rounding (the sums are taken in another order and on a
    rebased phase) would be a bug; 1e-10 relative is many orders above rounding and far below
    any statistical effect.
    """
    est = StreamingAllan(RATE, max_tau=400.0, exact=True, frame=777)
    feed_chunked(est, record, seed=1)
    res = est.result()
    assert 3000 < res.m[-1] <= 4000  # up to n / min_clusters, like the batch grid
    batch = allan_deviation(record, RATE, taus=res.m / RATE)
    np.testing.assert_array_equal(batch.m, res.m)
    np.testing.assert_allclose(res.avar, batch.avar, rtol=1e-10)
    np.testing.assert_allclose(res.edf, batch.edf, rtol=1e-10)
    np.testing.assert_allclose(res.ci_high, batch.ci_high, rtol=1e-10)


def test_default_mode_exact_up_to_base_and_strided_beyond(record):
    """Default mode: factors <= stride_base equal the batch; longer ones equal the strided sum."""
    est = StreamingAllan(RATE, max_tau=400.0)
    feed_chunked(est, record, seed=2)
    ms, strides, acc, cnt = est.sums()
    assert strides[ms <= 256].max() == 1 and strides[-1] > 1
    assert np.all(ms % strides == 0) and np.all(ms // strides <= 256)
    res = est.result()
    exact = strides[np.isin(ms, res.m)] == 1
    batch = allan_deviation(record, RATE, taus=res.m / RATE)
    np.testing.assert_allclose(res.avar[exact], batch.avar[exact], rtol=1e-10)
    x = _phase(record)
    for f in np.flatnonzero(strides > 1):
        ref, count = _reference_sums(x, ms[f], strides[f])
        assert np.all(cnt[f] == count)
        if count:
            np.testing.assert_allclose(acc[f], ref, rtol=1e-10)
    # The strided estimates are the same statistic from fewer terms: within a few per cent.
    assert np.max(np.abs(res.avar[~exact] / batch.avar[~exact] - 1)) < 0.05


def test_any_chunking_gives_identical_numbers(record):
    """Two different chunkings (and one block) give bit-identical results."""
    results = []
    for seed in (3, 4, None):
        est = StreamingAllan(RATE, max_tau=100.0, window_s=60.0)
        if seed is None:
            est.update(record)
        else:
            feed_chunked(est, record, seed)
        results.append((est.sums(), est.sums(window=True)))
    for other in results[1:]:
        for a, b in zip(results[0], other):
            for x, y in zip(a, b):
                np.testing.assert_array_equal(x, y)


def test_excluded_spans_and_gaps_pool_segments(record):
    """Left-out samples and stamp gaps restart the phase: pooled per-segment batch sums."""
    data = record[:12000]
    use = np.ones(len(data), bool)
    use[3000:3500] = False
    brk = np.zeros(len(data), bool)
    brk[8000] = True
    est = StreamingAllan(RATE, taus=[0.01, 0.05, 0.3, 1.0, 2.56], frame=500)
    feed_chunked(est, data, seed=5, use=use, brk=brk)
    ms, _, acc, cnt = est.sums()
    segments = [data[:3000], data[3500:8000], data[8000:]]
    for f, m in enumerate(ms):
        total, count = 0.0, 0
        for seg in segments:
            s, c = _reference_sums(_phase(seg), m)
            total, count = total + s, count + c
        assert np.all(cnt[f] == count)
        np.testing.assert_allclose(acc[f], total, rtol=1e-10)
    assert est.n_used == len(data) - 500


def test_memory_constant_from_1e5_to_1e7_samples():
    """The estimator's buffers after 10^5 and 10^7 samples have the same size (1 axis)."""
    est = StreamingAllan(1000.0, axes=('gyro_x',), max_tau=1000.0, frame=65536)
    rng = np.random.default_rng(0)
    block = 100_000
    sizes = {}
    before = est.memory_bytes()
    for i in range(1, 101):
        est.update(rng.standard_normal((block, 1)))
        if i in (1, 100):
            sizes[i * block] = est.memory_bytes()
    assert est.n_used == 10_000_000
    assert sizes[100_000] == sizes[10_000_000] == before
    assert before < 2_000_000  # m up to 10^6 tracked in well under 2 MB
    res = est.result()
    # White noise of unit variance: AVAR(m) = 1 / m (at tau0 = 1 ms, in sample units).
    assert abs(res.avar[0, 0] * res.m[0] - 1.0) < 0.01


def test_pipeline_memory_constant():
    """Stamp monitor + gate + estimator: the same buffers after 5x10^4 and 2x10^5 samples."""
    pipe = OnlineAllan(100.0)
    rng = np.random.default_rng(1)
    sizes = []
    for i in range(4):
        t = (np.arange(50_000) + i * 50_000) / 100.0
        pipe.feed(t, 1e-3 * rng.standard_normal((50_000, 6)))
        sizes.append(pipe.memory_bytes())
    assert len(set(sizes)) == 1


def test_sliding_window_shows_a_change():
    """
    White noise that triples: the 60 s window reports the new level, the whole run does not.

    Window terms are defined exactly (terms whose newest sample lies in the newest buckets),
    so the windowed sum equals the batch sum over those terms to rounding.
    """
    rng = np.random.default_rng(7)
    data = np.concatenate([1e-3 * rng.standard_normal((30000, 1)),
                           3e-3 * rng.standard_normal((12000, 1))])
    est = StreamingAllan(RATE, axes=('gyro_x',), taus=[0.01, 0.1, 1.0], window_s=60.0,
                         window_buckets=12)
    feed_chunked(est, data, seed=8)
    whole, window = est.result(), est.result(window=True)
    ratio_window = np.sqrt(window.avar[0, 0]) / (3e-3 / np.sqrt(1.0))
    ratio_whole = np.sqrt(whole.avar[0, 0]) / 3e-3
    assert abs(ratio_window - 1) < 0.03  # ~5000 terms: 1 % standard error
    assert ratio_whole < 0.7
    ms, _, acc, cnt = est.sums(window=True)
    bucket_len = 500  # 60 s x 100 Hz / 12
    first = (len(data) - 1) // bucket_len * bucket_len - 11 * bucket_len
    x = _phase(data)
    for f, m in enumerate(ms):
        ref, count = _reference_sums(x, m, k_min=first - 2 * m + 1)
        assert np.all(cnt[f] == count)
        np.testing.assert_allclose(acc[f], ref, rtol=1e-9)


def test_online_allan_stamps_and_defaults(record):
    """online_allan: out-of-order stamps dropped, a gap splits; without them == batch."""
    data = record[:20000]
    t = np.arange(len(data)) / RATE
    plain = online_allan(data, RATE, t=t, gate=False)
    batch = allan_deviation(data, RATE, taus=plain.tau)
    small = plain.m <= 256
    np.testing.assert_allclose(plain.avar[small], batch.avar[small], rtol=1e-10)
    # Duplicate a block of stamps (a replayed burst): dropped, same numbers.
    t_dup = np.concatenate([t[:5000], t[4000:5000], t[5000:]])
    d_dup = np.concatenate([data[:5000], data[4000:5000] + 1.0, data[5000:]])
    again = online_allan(d_dup, RATE, t=t_dup, gate=False)
    np.testing.assert_array_equal(again.avar, plain.avar)


def test_factor_grid_rounding():
    """Strided factors are multiples of their stride, at most stride_base per stride."""
    ms, strides = factor_grid(1000.0, max_tau=3600.0, points_per_decade=10)
    assert ms[0] == 1 and ms[-1] <= 3_700_000 and np.all(np.diff(ms) > 0)
    assert np.all(ms % strides == 0) and np.all(ms // strides <= 256)
    assert np.all((strides == 1) | (ms // strides > 128))


@pytest.fixture(scope='module')
def per_axis_case(record):
    """
    12,000 samples; gyro_x bad (NaN, inf, 1e300) at 60 seeded random positions, accel_y at 3.

    Also a whole-sample excluded span (motion) and a stamp gap, as the node produces them.
    Returns the data with the bad values, the clean data, the per-axis ``use`` (n, 6), the
    whole-sample ``use`` (n,) and ``brk`` (n,).
    """
    clean = record[:12000].copy()
    rng = np.random.default_rng(11)
    bad = np.zeros(clean.shape, bool)
    bad[rng.choice(clean.shape[0], 60, replace=False), 0] = True
    bad[rng.choice(clean.shape[0], 3, replace=False), 4] = True
    dirty = clean.copy()
    dirty[bad] = rng.choice([np.nan, np.inf, -np.inf, 1e300], bad.sum())
    use = np.ones(clean.shape[0], bool)
    use[3000:3500] = False
    brk = np.zeros(clean.shape[0], bool)
    brk[8000] = True
    return dirty, clean, use[:, None] & ~bad, use, brk


def test_per_axis_left_out_values(per_axis_case):
    """
    Values left out on one axis only: that axis pools its own segments, the others are intact.

    The damaged axes equal the batch estimator applied to each of their segments (split at the
    motion span, the stamp gap and at every left-out value) and pooled, to 1e-10 relative
    (rounding only: the sums are taken in another order on a rebased phase); the other four
    axes are bit-identical to a run on the clean data with no per-axis mask.  The left-out
    values are NaN, inf and 1e300: never read (no RuntimeWarning).
    """
    dirty, clean, use2, use, brk = per_axis_case
    taus = [0.01, 0.05, 0.3, 1.0, 2.56]
    ref = StreamingAllan(RATE, taus=taus, frame=500)
    feed_chunked(ref, clean, seed=5, use=use, brk=brk)
    est = StreamingAllan(RATE, taus=taus, frame=500)
    with np.errstate(all='raise'):
        feed_chunked(est, dirty, seed=6, use=use2, brk=brk)
    ms, _, acc, cnt = est.sums()
    _, _, acc_ref, cnt_ref = ref.sums()
    intact = [1, 2, 3, 5]
    np.testing.assert_array_equal(acc[:, intact], acc_ref[:, intact])
    np.testing.assert_array_equal(cnt[:, intact], cnt_ref[:, intact])
    res, res_ref = est.result(), ref.result()
    np.testing.assert_array_equal(res.m, res_ref.m)
    for name in ('avar', 'edf', 'ci_low', 'ci_high'):
        np.testing.assert_array_equal(getattr(res, name)[:, intact],
                                      getattr(res_ref, name)[:, intact])
    for a in (0, 4):
        segments = split_segments(clean[:, a], ~use2[:, a], brk)
        pooled, count = pooled_batch(segments, ms, RATE)
        np.testing.assert_array_equal(cnt[:, a], count)
        np.testing.assert_allclose(acc[:, a] / (2.0 * ms * ms * cnt[:, a]), pooled, rtol=1e-10)
        # Reported where this axis's own terms span min_clusters x m samples, NaN elsewhere.
        enough = count + 2 * ms - 1 >= est.min_clusters * ms
        expected = np.where(enough, pooled, np.nan)[np.isin(ms, res.m)]
        np.testing.assert_allclose(res.avar[:, a], expected, rtol=1e-10)
    assert np.isnan(res.avar[-1, 0]) and np.isfinite(res.avar[-1, 1:]).all()
    # Counts: every axis loses the motion span; gyro_x and accel_y also their own bad values.
    assert est.n_offered == 12000 and est.n_used == 12000 - 500
    np.testing.assert_array_equal(est.n_used_axes, use2.sum(axis=0))
    assert est.n_used_axes[0] < est.n_used_axes[1] == 11500
    # Segments: 3 for the intact axes; gyro_x one more per bad value not adjacent to a cut.
    assert est._st.n_segments[1] == 3
    assert est._st.n_segments[0] == len(split_segments(clean[:, 0], ~use2[:, 0], brk))


def test_per_axis_masks_any_chunking_identical(per_axis_case):
    """Per-axis masks with a sliding window: any chunking gives bit-identical sums."""
    dirty, _, use2, _, brk = per_axis_case
    results = []
    for seed in (7, 8, None):
        est = StreamingAllan(RATE, max_tau=20.0, stride_base=16, window_s=30.0,
                             window_buckets=7, frame=700)
        if seed is None:
            est.update(dirty, use2, brk)
        else:
            feed_chunked(est, dirty, seed, use=use2, brk=brk)
        assert (est.strides > 1).any()
        results.append((est.sums(), est.sums(window=True), est.n_used_axes))
    for other in results[1:]:
        for x, y in zip(results[0][:2], other[:2]):
            for u, v in zip(x, y):
                np.testing.assert_array_equal(u, v)
        np.testing.assert_array_equal(results[0][2], other[2])


def test_per_axis_window_and_strides_match_clean_axes(per_axis_case):
    """Strided factors and the window: the intact axes still equal the clean run exactly."""
    dirty, clean, use2, use, brk = per_axis_case
    kw = {'max_tau': 20.0, 'stride_base': 16, 'window_s': 30.0, 'window_buckets': 7,
          'frame': 700}
    est, ref = StreamingAllan(RATE, **kw), StreamingAllan(RATE, **kw)
    feed_chunked(est, dirty, 9, use=use2, brk=brk)
    feed_chunked(ref, clean, 10, use=use, brk=brk)
    intact = [1, 2, 3, 5]
    for window in (False, True):
        for x, y in zip(est.sums(window)[2:], ref.sums(window)[2:]):
            np.testing.assert_array_equal(x[:, intact], y[:, intact])
    ms, strides, acc, cnt = est.sums()
    # gyro_x's strided sums: the stride-s terms of each of its own segments, pooled.
    for f in np.flatnonzero(strides > 1):
        total, count = 0.0, 0
        for seg in split_segments(clean[:, 0], ~use2[:, 0], brk):
            s, c = _reference_sums(_phase(seg[:, None]), ms[f], strides[f])
            total, count = total + s[0], count + c
        assert cnt[f, 0] == count
        if count:
            np.testing.assert_allclose(acc[f, 0], total, rtol=1e-10)


def test_per_axis_result_nan_where_an_axis_is_too_short():
    """Short segments on one axis: NaN (and EDF NaN) at the factors only it cannot reach."""
    rng = np.random.default_rng(12)
    data = rng.normal(0.0, 1.0, (5000, 2))
    use = np.ones(data.shape, bool)
    use[::50, 0] = False  # 49-sample segments: m <= 24 only
    est = StreamingAllan(RATE, axes=('gyro_x', 'gyro_y'), taus=[0.01, 0.2, 0.24, 0.25, 1.0])
    est.update(data, use)
    res = est.result()
    np.testing.assert_array_equal(res.m, [1, 20, 24, 25, 100])
    assert np.isfinite(res.avar[:3]).all() and np.isnan(res.avar[3:, 0]).all()
    assert np.isnan(res.edf[3:, 0]).all() and np.isnan(res.ci_high[3:, 0]).all()
    assert np.isfinite(res.avar[:, 1]).all() and np.isfinite(res.edf[:, 1]).all()
    with pytest.raises(ValueError, match='shape'):
        est.update(data, use[:, :1].T)
