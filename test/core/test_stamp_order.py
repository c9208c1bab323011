"""
One rule for out-of-order and repeated stamps: ``analyze`` and the allan node drop the same.

Seeded damage at many positions of a 100 Hz record: a stamp set back, a stamp repeated, a
stamp pushed a fraction of an interval ahead.  Isolated faults are dropped and named; a
stretch of them, or more than 1 in 1000 samples, refuses the record as before.
"""

from imu_allan.core.analysis import analyze_samples
from imu_allan.core.checks.stamp_order import drop_isolated, keep_increasing, MAX_DROPPED_SHARE
from imu_allan.core.live.health import StampMonitor
from imu_allan.errors import InputError
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

N = 20_000
RATE = 100.0


def _record(seed=0):
    rng = np.random.default_rng(seed)
    return Samples(t=1.7e9 + np.arange(N) / RATE, data=rng.normal(0.0, 1e-3, (N, 6)),
                   source='rec')


def _damage(t, idx, rng):
    """Damage the stamps at ``idx`` (isolated): back, repeated or slightly ahead."""
    t = t.copy()
    for i in idx.tolist():
        kind = int(rng.integers(0, 3))
        if kind == 0:
            t[i] = t[i - 1] - float(rng.uniform(0.0, 100.0))   # went backwards
        elif kind == 1:
            t[i] = t[i - 1]                                    # repeated
        else:
            # ahead of the next one (but not the one after): sample i + 1 is the odd one
            t[i] = t[i + 1] + 0.5 / RATE
    return t


def _isolated_positions(rng, k):
    """Return k positions, no two within 3 samples, none at the ends."""
    while True:
        idx = np.sort(rng.choice(np.arange(2, N - 3), size=k, replace=False))
        if k < 2 or np.diff(idx).min() > 3:
            return idx


def test_offline_and_online_drop_the_same_samples():
    """drop_isolated == StampMonitor fed in random batches, over 40 seeded damage patterns."""
    t0 = _record().t
    for seed in range(40):
        rng = np.random.default_rng(seed)
        t = _damage(t0, _isolated_positions(rng, int(rng.integers(1, 15))), rng)
        keep, problem = drop_isolated(t)
        assert problem is None and keep is not None
        mon = StampMonitor(RATE)
        cuts = np.sort(rng.choice(np.arange(1, N), size=30, replace=False))
        online = np.concatenate([mon.check(part)[0] for part in np.split(t, cuts)])
        assert np.array_equal(online, keep)
        assert mon.out_of_order == int((~keep).sum())
        kept = t[keep]
        assert np.all(np.diff(kept) > 0)


def test_isolated_faults_dropped_named_and_the_rest_unchanged():
    """The damaged record analyses as the record without those samples, with a warning."""
    rec = _record(1)
    rng = np.random.default_rng(7)
    idx = _isolated_positions(rng, 5)
    t = rec.t.copy()
    t[idx] = t[idx - 1]                      # repeated stamps: the later sample is dropped
    damaged = Samples(t=t, data=rec.data, source='rec')
    got = analyze_samples(damaged)
    keep = np.ones(N, bool)
    keep[idx] = False
    ref = analyze_samples(Samples(t=rec.t[keep], data=rec.data[keep], source='rec'))
    assert got.n_samples == N - 5
    np.testing.assert_array_equal(got.result.adev, ref.result.adev)
    text = [w for w in got.warnings if 'out-of-order' in w]
    assert len(text) == 1 and text[0].startswith('5 isolated out-of-order or repeated')
    for i in idx[:3].tolist():
        assert f'{i} (t={t[i]:.9f} s)' in text[0]
    # The record analysed is handed back (the command reports on it, not rule-applied again)
    assert np.array_equal(got.samples.t, rec.t[keep])
    assert np.array_equal(got.samples.data, rec.data[keep])
    assert got.samples.warnings == text and damaged.warnings == []
    assert ref.samples.warnings == []


def test_an_intact_record_is_handed_back_as_it_was():
    """No stamp dropped: Analysis.samples is the input itself (no copy of the record)."""
    rec = _record(3)
    assert analyze_samples(rec).samples is rec


@pytest.mark.parametrize('case', ['two_in_a_row', 'too_many', 'run_backwards', 'far_ahead'])
def test_faults_that_are_not_isolated_refuse_the_record(case):
    """A stretch of bad stamps, or more than 1 in 1000: refused, the threshold named."""
    rec = _record(2)
    t = rec.t.copy()
    if case == 'two_in_a_row':
        t[500] = t[501] = t[499] - 1.0
    elif case == 'too_many':
        limit = int(MAX_DROPPED_SHARE * N)
        t[10:10 + 4 * (limit + 1):4] -= 1.0
    elif case == 'run_backwards':
        t[5000:] -= 2.0
    else:
        t[700] += 1.0     # hides the 100 samples after it
    with pytest.raises(InputError, match='do not increase.*not isolated'):
        analyze_samples(Samples(t=t, data=rec.data, source='rec'))


def test_keep_increasing_carries_the_running_maximum():
    """A batch after a later stamp keeps only what is later; NaN never kept nor counted up."""
    t = np.array([1.0, np.nan, 2.0, 1.5, 3.0])
    assert keep_increasing(t).tolist() == [True, False, True, False, True]
    assert keep_increasing(t, last=2.5).tolist() == [False, False, False, False, True]
