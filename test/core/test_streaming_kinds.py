"""
Streaming modified Allan (MDEV) and overlapping Hadamard (OHDEV) variances against batch ones.

The oracles: a readable numpy reference written here from NIST SP1065 eq. 14 (MVAR, inner sums
of second differences formed as moving sums) and eq. 18 (OHVAR), computed on the de-meaned
samples (both variances ignore a constant rate), and allantools (``mdev``, ``ohdev`` with
``data_type='freq'``), an implementation that is not ours.  Where every term is formed (stride 1:
``exact=True`` or m <= stride_base) the streaming sums must equal them to float rounding:
1e-10 relative is orders above rounding (measured 1e-14 .. 1e-12) and far below any statistic.
"""

from core.segment_cases import feed_chunked, split_segments
from imu_allan.core.live.online import online_allan, OnlineAllan, StagedEstimate
from imu_allan.core.live.streaming import parse_estimators, StreamingAllan
from imu_allan.errors import InputError
import numpy as np
import pytest

RATE = 100.0
KINDS = ('mdev', 'ohdev')


def reference_sums(data, m, kind, stride=1, dtype=np.float64, k_min=0):
    """
    Sum of squared terms and their count, SP1065 eq. 14 (mdev) or eq. 18 (ohdev), one segment.

    ``data`` (n, A) rate samples; phase x = cumulative sum (x_0 = 0) of the de-meaned samples.
    MVAR: the inner sum over i = j .. j+m-1 of the second differences at lag m (a moving sum
    of m of them); OHVAR: third differences at lag m.  Only terms j (k) that are multiples of
    ``stride`` (the streaming estimator's strided factors), and from ``k_min`` on.
    """
    y = np.asarray(data, dtype=dtype)
    if y.shape[0] + 2 - 3 * m <= 0:  # too short for one term
        return np.zeros(y.shape[1]), 0
    y = y - y.mean(axis=0)
    x = np.zeros((y.shape[0] + 1, y.shape[1]), dtype)
    x[1:] = np.cumsum(y, axis=0)
    if kind == 'ohdev':
        terms = x[3 * m:] - 3 * x[2 * m:x.shape[0] - m] + 3 * x[m:x.shape[0] - 2 * m] \
            - x[:x.shape[0] - 3 * m]
    else:
        d2 = x[2 * m:] - 2 * x[m:x.shape[0] - m] + x[:x.shape[0] - 2 * m]
        c = np.zeros((d2.shape[0] + 1, d2.shape[1]), dtype)
        c[1:] = np.cumsum(d2, axis=0)
        terms = c[m:] - c[:c.shape[0] - m]
    terms = terms[::stride][k_min:]
    return (terms * terms).sum(axis=0), terms.shape[0]


def variance(kind, ms, acc, cnt):
    """MVAR = sum / (2 m^4 K), OHVAR = sum / (6 m^2 K), sample units."""
    m = np.asarray(ms, dtype=float)[:, None]
    return acc / ((2.0 * m ** 4 if kind == 'mdev' else 6.0 * m ** 2) * cnt)


def test_exact_mode_equals_reference_and_allantools(record):
    """exact=True: every factor's MVAR and OHVAR equal our reference and allantools (1e-10)."""
    allantools = pytest.importorskip('allantools')
    record = record[:20000]
    est = StreamingAllan(RATE, max_tau=20.0, exact=True, frame=777,
                         estimators='oadev,mdev,ohdev')
    feed_chunked(est, record, seed=1)
    for kind in KINDS:
        ms, strides, acc, cnt = est.sums(kind=kind)
        assert (strides == 1).all() and ms[-1] == 2000
        ref, count = zip(*[reference_sums(record, m, kind) for m in ms])
        ref, count = np.array(ref), np.array(count)
        np.testing.assert_array_equal(cnt, np.repeat(count[:, None], 6, axis=1))
        np.testing.assert_allclose(acc, ref, rtol=1e-10)
        dev = est.deviation(kind)
        # Reported factors: the data span min_clusters (10) x m samples, as for OADEV.
        assert dev.m[-1] == 2000
        np.testing.assert_allclose(dev.tau, dev.m / RATE)
        np.testing.assert_allclose(dev.dev ** 2, variance(kind, ms, acc, cnt)[:dev.m.size],
                                   rtol=1e-12)
        # allantools (data de-meaned: its phase is the raw cumulative sum, on which a 1 g
        # offset costs it digits; the variances ignore a constant).
        fn = getattr(allantools, kind)
        for a in range(6):
            y = record[:, a] - record[:, a].mean()
            taus, dev_at, _, n_at = fn(y, rate=RATE, data_type='freq', taus=dev.tau)
            np.testing.assert_allclose(taus, dev.tau, rtol=1e-12)
            np.testing.assert_array_equal(n_at, count[:dev.m.size])
            np.testing.assert_allclose(dev.dev[:, a], dev_at, rtol=1e-10)


def test_exact_mode_equals_package_deviation(record):
    """
    exact=True: MDEV and OHDEV equal ``imu_allan.deviation(kind=...)``, the batch estimators.

    Same averaging factors and term counts (Stable32's '#'), deviations to 1e-10 relative
    (measured 6e-14), on 20,000 x 6 samples with gravity on accel_z.
    """
    from imu_allan import deviation
    record = record[:20000]
    est = StreamingAllan(RATE, max_tau=20.0, exact=True, estimators='mdev,ohdev')
    feed_chunked(est, record, seed=12)
    for kind in KINDS:
        dev = est.deviation(kind)
        batch = deviation(record, RATE, kind=kind, taus=dev.tau)
        np.testing.assert_array_equal(batch.m, dev.m)
        _, _, _, cnt = est.sums(kind=kind)
        np.testing.assert_array_equal(batch.n_terms, cnt[:dev.m.size, 0])
        np.testing.assert_allclose(dev.dev, batch.dev, rtol=1e-10)


def test_default_mode_exact_up_to_base_strided_beyond(record):
    """Default mode: m <= 256 every term; longer factors equal the strided reference sums."""
    record = record[:20000]
    est = StreamingAllan(RATE, max_tau=100.0, estimators=['mdev', 'ohdev'])
    feed_chunked(est, record, seed=2)
    for kind in KINDS:
        ms, strides, acc, cnt = est.sums(kind=kind)
        assert strides[ms <= 256].max() == 1 and strides[-1] > 1
        for f in range(ms.size):
            ref, count = reference_sums(record, ms[f], kind, strides[f])
            assert np.all(cnt[f] == count)
            np.testing.assert_allclose(acc[f], ref, rtol=1e-10)


def test_oadev_bit_identical_with_or_without_extra_kinds(record):
    """Adding mdev and ohdev changes nothing in the AVAR sums (the node's oadev numbers)."""
    plain = StreamingAllan(RATE, max_tau=100.0, window_s=60.0)
    more = StreamingAllan(RATE, max_tau=100.0, window_s=60.0, estimators='mdev,ohdev')
    feed_chunked(plain, record, seed=3)
    feed_chunked(more, record, seed=4)
    for window in (False, True):
        for x, y in zip(plain.sums(window), more.sums(window)):
            np.testing.assert_array_equal(x, y)
    assert plain.kinds == ('oadev',) and more.kinds == ('oadev', 'mdev', 'ohdev')
    with pytest.raises(ValueError, match='not computed'):
        plain.sums(kind='mdev')


@pytest.fixture(scope='module')
def per_axis_case(record):
    """
    12,000 samples: gyro_x bad (NaN, inf, 1e300) at 40 seeded positions, accel_y at 3.

    Also a whole-sample excluded span (motion) and a stamp gap.  Returns the data with the bad
    values, the clean data, the per-axis ``use`` (n, 6), the whole-sample ``use`` and ``brk``.
    """
    clean = record[:12000].copy()
    rng = np.random.default_rng(11)
    bad = np.zeros(clean.shape, bool)
    bad[rng.choice(clean.shape[0], 40, replace=False), 0] = True
    bad[rng.choice(clean.shape[0], 3, replace=False), 4] = True
    dirty = clean.copy()
    dirty[bad] = rng.choice([np.nan, np.inf, -np.inf, 1e300], bad.sum())
    use = np.ones(clean.shape[0], bool)
    use[3000:3500] = False
    brk = np.zeros(clean.shape[0], bool)
    brk[8000] = True
    return dirty, clean, use[:, None] & ~bad, use, brk


def test_segments_and_per_axis_masks_pool_segments(per_axis_case):
    """
    Gaps, motion and per-axis rejected values: each axis pools its own segments' sums.

    The intact axes are bit-identical to a run on the clean data with whole-sample masks; the
    damaged ones equal the reference on each of their segments, pooled (1e-10); strided
    factors (stride_base 16) included; left-out values are never read.
    """
    dirty, clean, use2, use, brk = per_axis_case
    kw = {'max_tau': 20.0, 'stride_base': 16, 'estimators': 'mdev,ohdev', 'frame': 500}
    est, ref = StreamingAllan(RATE, **kw), StreamingAllan(RATE, **kw)
    with np.errstate(all='raise'):
        feed_chunked(est, dirty, seed=6, use=use2, brk=brk)
    feed_chunked(ref, clean, seed=5, use=use, brk=brk)
    intact = [1, 2, 3, 5]
    for kind in KINDS:
        ms, strides, acc, cnt = est.sums(kind=kind)
        _, _, acc_ref, cnt_ref = ref.sums(kind=kind)
        np.testing.assert_array_equal(acc[:, intact], acc_ref[:, intact])
        np.testing.assert_array_equal(cnt[:, intact], cnt_ref[:, intact])
        assert (strides > 1).any()
        for a in (0, 1, 4):
            segments = split_segments(clean[:, a], ~use2[:, a], brk)
            assert len(segments) >= (3 if a == 1 else 4)
            for f in range(ms.size):
                total, count = 0.0, 0
                for seg in segments:
                    if seg.size + 2 - 3 * ms[f] > 0:
                        s, c = reference_sums(seg[:, None], ms[f], kind, strides[f])
                        total, count = total + s[0], count + c
                assert cnt[f, a] == count, (kind, a, ms[f])
                if count:
                    np.testing.assert_allclose(acc[f, a], total, rtol=1e-10)
        dev = est.deviation(kind)
        n_eff = cnt * strides[:, None] + 3 * ms[:, None] - (2 if kind == 'mdev' else 1)
        ok = (cnt > 0) & (n_eff >= 10 * ms[:, None])
        shown = ok.any(axis=1)
        np.testing.assert_array_equal(dev.m, ms[shown])
        np.testing.assert_array_equal(np.isfinite(dev.dev), ok[shown])
        assert np.isnan(dev.dev[-1, 0]) and np.isfinite(dev.dev[:, 1]).all()


def test_any_chunking_identical_with_window_and_masks(per_axis_case):
    """Any chunking (and one block) gives bit-identical sums of every kind, window included."""
    dirty, _, use2, _, brk = per_axis_case
    results = []
    for seed in (7, 8, None):
        est = StreamingAllan(RATE, max_tau=20.0, stride_base=16, window_s=30.0,
                             window_buckets=7, frame=700, estimators='mdev,ohdev')
        if seed is None:
            est.update(dirty, use2, brk)
        else:
            feed_chunked(est, dirty, seed, use=use2, brk=brk)
        results.append([est.sums(window, kind=kind) for window in (False, True)
                        for kind in est.kinds])
    for other in results[1:]:
        for a, b in zip(results[0], other):
            for x, y in zip(a, b):
                np.testing.assert_array_equal(x, y)


def test_window_sums_are_the_newest_terms():
    """Sliding window: MVAR and OHVAR sums of exactly the terms ending in the newest buckets."""
    rng = np.random.default_rng(7)
    data = np.concatenate([1e-3 * rng.standard_normal((30000, 1)),
                           3e-3 * rng.standard_normal((12000, 1))])
    est = StreamingAllan(RATE, axes=('gyro_x',), taus=[0.01, 0.1, 1.0], window_s=60.0,
                         window_buckets=12, estimators='mdev,ohdev')
    feed_chunked(est, data, seed=8)
    bucket_len = 500  # 60 s x 100 Hz / 12
    first = (len(data) - 1) // bucket_len * bucket_len - 11 * bucket_len
    for kind in KINDS:
        ms, _, acc, cnt = est.sums(window=True, kind=kind)
        for f, m in enumerate(ms):
            # The term of j (k) ends at sample j + 3m - 2 (mdev: S_{j+3m} sums x up to
            # x_{j+3m-1}) or k + 3m - 1 (ohdev), 0-based: booked in the bucket of that sample.
            k_min = first - 3 * m + (2 if kind == 'mdev' else 1)
            ref, count = reference_sums(data, m, kind, k_min=k_min)
            assert cnt[f, 0] == count
            np.testing.assert_allclose(acc[f], ref, rtol=1e-9)
        # The window holds only the tripled noise: its deviation at m = 1 is about
        # sqrt(9 / 3.29) = 1.65 x the whole run's (30,000 samples at 1, 12,000 at 3 x the
        # noise); more than 1.5 x (about 5,600 terms: 2-3 % standard error).
        assert (est.deviation(kind, window=True).dev[0, 0]
                / est.deviation(kind).dev[0, 0]) > 1.5


def test_long_stream_with_1g_offset_equals_extended_precision_reference():
    """
    10^6 samples at 1 kHz with a 1 g offset and a rate random walk: 1e-9 of a long-double ref.

    The raw cumulative sum of the phase reaches 5x10^12 here (S ~ n^2 g / 2); the estimator
    keeps S relative to its newest value and slope (module docstring), so no digits are lost:
    measured 1e-13 .. 1e-12 (10^7 samples: below 1e-12, docs/online.md).  The reference runs in
    numpy's long double (64-bit mantissa on x86-64) on the de-meaned samples.
    """
    rng = np.random.default_rng(3)
    n = 1_000_000
    y = 9.80665 + 0.025 * rng.standard_normal(n) + np.cumsum(1e-6 * rng.standard_normal(n))
    taus = [0.001, 0.002, 0.01, 0.1, 1.0, 10.0, 30.0]
    est = StreamingAllan(1000.0, axes=('accel_z',), taus=taus, exact=True,
                         estimators='mdev,ohdev', frame=65536)
    for i in range(0, n, 300_000):
        est.update(y[i:i + 300_000, None])
    for kind in KINDS:
        ms, _, acc, cnt = est.sums(kind=kind)
        ref = np.array([float(reference_sums(y[:, None], m, kind,
                                             dtype=np.longdouble)[0][0]) for m in ms])
        np.testing.assert_allclose(acc[:, 0], ref, rtol=1e-9)


def test_memory_fixed_and_bounded():
    """
    The buffers do not grow from 0 to 3x10^5 samples; mdev + ohdev less than 3x oadev alone.

    Per level the phase history grows from 2 to 3 x (largest m / s) points and an S history of
    3 x as many is added; per factor two more running sums (and window buckets).
    """
    rng = np.random.default_rng(0)
    kw = {'axes': ('gyro_x',), 'max_tau': 1000.0, 'frame': 4096}
    plain = StreamingAllan(1000.0, **kw)
    est = StreamingAllan(1000.0, estimators='oadev,mdev,ohdev', **kw)
    before = est.memory_bytes()
    for _ in range(3):
        est.update(rng.standard_normal((100_000, 1)))
    assert est.memory_bytes() == before and est.n_used == 300_000
    assert 2 * plain.memory_bytes() < before < 3 * plain.memory_bytes()


def test_parse_estimators():
    """Lists or comma strings; oadev always first; unknown kinds and non-text refused."""
    assert parse_estimators('ohdev, MDEV') == ('oadev', 'mdev', 'ohdev')
    assert parse_estimators(['oadev']) == ('oadev',)
    assert parse_estimators('') == ('oadev',)
    with pytest.raises(InputError, match='estimators: unknown estimator.s. totdev'):
        parse_estimators('oadev,totdev')
    with pytest.raises(InputError, match='estimators: expected a list'):
        parse_estimators(3)


def test_pipeline_and_staged_estimate_carry_the_extra_kinds(record):
    """The pipeline passes ``estimators`` on; a staged cycle freezes every kind's curve."""
    pipe = OnlineAllan(RATE, gate=False, estimators='mdev,ohdev')
    t = np.arange(20000) / RATE
    pipe.feed(t[:12345], record[:12345])
    cycle = StagedEstimate(pipe)
    pipe.feed(t[12345:20000], record[12345:20000])  # after the freeze: not in this cycle
    while not cycle.step():
        pass
    assert set(cycle.deviations) == set(KINDS)
    frozen = StreamingAllan(RATE, estimators='mdev,ohdev')
    frozen.update(record[:12345])
    for kind in KINDS:
        np.testing.assert_array_equal(cycle.deviations[kind].dev, frozen.deviation(kind).dev)
    assert online_allan(record[:5000], RATE, gate=False).tau.size > 0
    assert set(pipe.deviations()) == set(KINDS)
