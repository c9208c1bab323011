"""The bounded-memory online Allan estimator against the batch overlapping estimator."""

from imu_allan.core.allan import allan_deviation
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.online import online_allan, OnlineAllan
from imu_allan.core.simulate import simulate
from imu_allan.core.streaming import factor_grid, StreamingAllan
import numpy as np
import pytest

RATE = 100.0


@pytest.fixture(scope='module')
def record():
    """40,000 samples (400 s) of the thesis 3DM-GX3-25 model, gravity on accel_z."""
    data = simulate(thesis_gx3_25_model(), 40000, RATE, seed=5)
    data[:, 5] += 9.80665
    return data


def _feed_chunked(est, data, seed, use=None, brk=None):
    rng = np.random.default_rng(seed)
    i = 0
    while i < data.shape[0]:
        n = int(rng.integers(1, 3000))
        est.update(data[i:i + n], None if use is None else use[i:i + n],
                   None if brk is None else brk[i:i + n])
        i += n


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
    _feed_chunked(est, record, seed=1)
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
    _feed_chunked(est, record, seed=2)
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
        assert cnt[f] == count
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
            _feed_chunked(est, record, seed)
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
    _feed_chunked(est, data, seed=5, use=use, brk=brk)
    ms, _, acc, cnt = est.sums()
    segments = [data[:3000], data[3500:8000], data[8000:]]
    for f, m in enumerate(ms):
        total, count = 0.0, 0
        for seg in segments:
            s, c = _reference_sums(_phase(seg), m)
            total, count = total + s, count + c
        assert cnt[f] == count
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
    _feed_chunked(est, data, seed=8)
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
        assert cnt[f] == count
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
