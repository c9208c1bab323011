"""
Property-based damage of the three bag readers (MCAP, sqlite3, ROS 1), many seeds.

Hypothesis draws bit flips (1 to 30 anywhere in the file) and an optional cut from a valid
300-sample bag of each storage, derandomized, 500 examples per storage.  The property is the
issue's rule, stronger than "no exception" (:mod:`.test_hostile_fuzz`): the read gives the
same samples, or different samples with a warning that names the damage, or InputError with
one line; never a traceback, never a hang (10 s alarm), never a changed result without a
warning where the container can know (MCAP: chunk CRCs; sqlite3: whatever ``PRAGMA
integrity_check`` sees; ROS 1 has no checksums at all, which its integrity note says).
"""

from formats.test_hostile_fuzz import no_hang
from formats.test_hostile_sqlite import integrity
from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
from imu_allan.errors import InputError
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

N = 300
EXAMPLES = 500
PROPERTY = settings(derandomize=True, max_examples=EXAMPLES, deadline=None, database=None,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])


def _samples():
    rng = np.random.default_rng(3)
    return Samples(t=1.7e9 + np.arange(N) / 100.0, data=rng.normal(0.0, 1e-3, (N, 6)))


@pytest.fixture(scope='module')
def valid(tmp_path_factory):
    """Return {storage: (bytes, suffix, samples as read)} of one valid bag per storage."""
    d = tmp_path_factory.mktemp('valid')
    out = {}
    for storage, suffix in (('mcap', '.mcap'), ('sqlite3', '.db3')):
        folder = write_imu_bag(d / storage, _samples(), storage=storage)
        path = next(folder.glob(f'*{suffix}'))
        out[storage] = (path.read_bytes(), suffix, read_bag(path))
    write_imu_bag(d / 'b.bag', _samples(), storage='ros1')
    out['ros1'] = ((d / 'b.bag').read_bytes(), '.bag', read_bag(d / 'b.bag'))
    return out


def _container_saw_damage(storage, path, got):
    """Return True if the container itself could know the file is damaged."""
    if storage == 'sqlite3':
        return bool(integrity(path))
    if storage == 'mcap':
        return 'no checksums' not in got.integrity and 'carry no CRC' not in got.integrity
    return False   # ROS 1: no checksums (the integrity note says so)


@pytest.mark.slow
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3', 'ros1'])
@PROPERTY
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 7)),
                      min_size=1, max_size=30),
       cut=st.one_of(st.just(1.0), st.floats(0.05, 1.0)))
def test_damaged_bag_same_or_warned_or_refused(valid, tmp_path, storage, flips, cut):
    """Same samples, a warning, or one-line InputError; a change the container saw is warned."""
    raw, suffix, ref = valid[storage]
    buf = bytearray(raw[:max(1, int(len(raw) * cut))])
    for where, bit in flips:
        buf[int(where * len(buf))] ^= 1 << bit
    path = tmp_path / f'damaged{suffix}'
    path.write_bytes(bytes(buf))
    with no_hang():
        try:
            got = read_bag(path)
        except InputError as exc:
            assert '\n' not in str(exc) and str(exc).strip()
            return
    assert got.t.ndim == 1 and got.data.shape == (got.t.shape[0], 6)
    assert all(isinstance(w, str) and '\n' not in w for w in got.warnings)
    same = (got.t.shape == ref.t.shape and np.array_equal(got.t, ref.t)
            and np.array_equal(got.data, ref.data))
    if same or got.warnings:
        return
    assert not _container_saw_damage(storage, path, got), 'changed result, no warning'
    assert 'no checksums' in got.integrity or 'carry no CRC' in got.integrity
