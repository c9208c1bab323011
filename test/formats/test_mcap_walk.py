"""
The compiled MCAP chunk walk (bag_kernels.mcap_walk) against the numpy walk it stands in for.

Each bag is read twice through ``read_bag``: once with the numpy walk of ``McapScan._walk``
(the readable reference: the compiled module lookup returns None) and once with the compiled
walk forced on (its size threshold set to 0); stamps, values, frame id and warnings (which
carry the counts of damaged messages and lost chunks) must be identical, and the compiled walk
must have decoded messages itself.  The bags come from the generators of test_bags.py, the
converted Jackal bag of the shared data and damage made here.
"""

import json
import subprocess
import sys

from conftest import SHARED_DATA
from formats.test_bags import (
    _samples,
    bad_nanosecond_bag,
    big_message_bag,
    damaged_copies,
    mixed_frame_bag,
)
from formats.test_sqlite_walk import _outcome, _same_outcome
from imu_allan.formats import mcap_scan
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.mcap_scan import McapScan
import numpy as np
import pytest

JACKAL_MCAP = SHARED_DATA / 'bags' / 'jackal_test2_mcap'


@pytest.fixture
def both(monkeypatch):
    """Return read(path, topic) -> (numpy walk outcome, compiled walk outcome, rows decoded)."""
    decoded = []
    plain = McapScan._compiled_walk

    def counting(self, u8, views, pos, end):
        before = sum(c.count for c in self.collectors.values())
        stop = plain(self, u8, views, pos, end)
        decoded.append(sum(c.count for c in self.collectors.values()) - before)
        return stop
    monkeypatch.setattr(McapScan, '_compiled_walk', counting)

    def read(path, topic=None):
        with monkeypatch.context() as m:
            m.setattr(mcap_scan, 'compiled_walks', lambda large: None)
            ref = _outcome(path, topic)
        assert not decoded
        with monkeypatch.context() as m:
            m.setattr(mcap_scan, 'COMPILED_MIN_BYTES', 0)
            fast = _outcome(path, topic)
        n = sum(decoded)
        decoded.clear()
        return ref, fast, n
    return read


def test_mixed_frame_ids_and_other_topics(tmp_path, both):
    """Seven CDR paddings interleaved on one topic, another Imu topic beside it: both topics."""
    path = mixed_frame_bag(tmp_path, 'mcap')
    for topic, n in (('/imu/mixed', 140), ('/imu/base', 300)):
        ref, fast, decoded = both(path, topic)
        assert ref[0] == 'samples' and ref[1].shape == (n,)
        assert decoded == n and _same_outcome(ref, fast), topic
    assert fast[3] == 'imu_link' and ref[3] == 'imu_link'


def test_two_wanted_topics_in_one_scan(tmp_path, monkeypatch):
    """
    Without a topic both Imu topics are collected, the same with the compiled walk.

    It decodes the first topic and leaves the other's messages to the numpy walk.
    """
    path = next(mixed_frame_bag(tmp_path, 'mcap').glob('*.mcap'))
    results = []
    for compiled in (False, True):
        with monkeypatch.context() as m:
            if compiled:
                m.setattr(mcap_scan, 'COMPILED_MIN_BYTES', 0)
            else:
                m.setattr(mcap_scan, 'compiled_walks', lambda large: None)
            scan = McapScan(path)
            scan.run()
        assert (scan._kernel is not None) == compiled
        results.append({t: c.result() for t, c in scan.collectors.items()}
                       | {'counts': dict(scan.counts)})
    ref, fast = results
    assert sorted(ref) == sorted(fast) == ['/imu/base', '/imu/mixed', 'counts']
    assert ref['counts'] == fast['counts']
    for topic in ('/imu/base', '/imu/mixed'):
        assert all(np.array_equal(a, b) for a, b in zip(ref[topic], fast[topic])), topic


def test_impossible_nanoseconds_counted_the_same(tmp_path, both):
    """The three messages with nanosec >= 1e9 are dropped and counted by both walks."""
    path, s, bad = bad_nanosecond_bag(tmp_path, 'mcap')
    ref, fast, decoded = both(path, '/imu/n')
    assert decoded and _same_outcome(ref, fast)
    assert fast[1].shape == (117,)
    assert any('3 damaged message(s)' in w for w in fast[4]), fast[4]


def test_other_topics_and_long_frame_ids(tmp_path, both):
    """
    Large Strings between the Imu messages, and Imu messages with a 5000-byte frame id.

    The compiled walk counts the Strings and decodes the ordinary Imu messages; it cannot tell
    every long one from damage by itself, so it hands them to the generic deserializer.
    """
    path, s = big_message_bag(tmp_path, 'mcap')
    ref, fast, decoded = both(path)
    assert decoded == 3000 and _same_outcome(ref, fast)
    assert np.array_equal(fast[2], s.data)


@pytest.mark.parametrize('compress', [False, True])
def test_plain_and_zstd_chunks(tmp_path, both, compress):
    """Chunks walked in place in the mapped file, and decompressed ones: the same."""
    path = tmp_path / 'z'
    s = _samples(5000)
    write_imu_bag(path, s, storage='mcap', compress=compress)
    ref, fast, decoded = both(path)
    assert decoded == 5000 and _same_outcome(ref, fast)
    assert np.array_equal(fast[1], s.t)


def test_jackal_bag_converted_by_rosbags(shared_data, both):
    """A third-party conversion (rosbags-convert, MCAP version 8): the same 3061 messages."""
    ref, fast, decoded = both(JACKAL_MCAP)
    assert decoded == 3061 and _same_outcome(ref, fast)


def test_cut_file(tmp_path, both):
    """A file cut in the middle: the complete chunks read, the same."""
    path = tmp_path / 'c'
    write_imu_bag(path, _samples(20000), storage='mcap')
    raw = next(path.glob('*.mcap')).read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(raw[:len(raw) // 2 + 1234])
    ref, fast, decoded = both(cut)
    assert decoded and _same_outcome(ref, fast)
    assert 1000 < fast[1].shape[0] < 20000


@pytest.mark.parametrize('compress', [False, True])
def test_random_damage_same_outcome(tmp_path, both, compress):
    """
    Seeded random overwrites (1-63 bytes at 1-3 places) or cuts: the same outcome, always.

    12 variants of a 20000-message bag (several chunks, checked ahead on threads).
    """
    path = tmp_path / 'good'
    write_imu_bag(path, _samples(20000), storage='mcap', compress=compress)
    raw = next(path.glob('*.mcap')).read_bytes()
    kinds = set()
    for k, data in enumerate(damaged_copies(raw, seed=29 + compress, count=12, first=64)):
        bad = tmp_path / f'bad{k}.mcap'
        bad.write_bytes(data)
        ref, fast, _ = both(bad)
        assert _same_outcome(ref, fast), k
        kinds.add(ref[0])
        if ref[0] == 'samples':
            kinds.update(w.split(' ')[0] for w in ref[4])
    assert 'samples' in kinds and 'corrupt' in kinds, kinds


_NO_NUMBA = """
import json, sys
sys.modules['numba'] = None
from imu_allan.formats import mcap_scan
from imu_allan.formats.bag_reader import read_bag
mcap_scan.COMPILED_MIN_BYTES = 0
r = read_bag(sys.argv[1])
print(json.dumps([r.t.tolist(), r.data.tolist(), r.warnings]))
"""


def test_without_numba_the_numpy_walk_reads_the_same(tmp_path):
    """Without numba (optional) the numpy walk reads: the same numbers, and no error."""
    path, s = big_message_bag(tmp_path, 'mcap')
    out = subprocess.run([sys.executable, '-c', _NO_NUMBA, str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    t, data, warnings = json.loads(out.stdout)
    r = read_bag(path)
    assert np.array_equal(np.array(t), r.t) and np.array_equal(np.array(data), r.data)
    assert warnings == r.warnings


def test_chunk_checks_run_ahead_and_find_the_same_damage(tmp_path, monkeypatch):
    """
    A bad CRC found on the threads that open chunks ahead is reported as without them.

    With the summary's chunk list the chunks are opened ahead of the walk; the damaged one is
    named by its offset and skipped, the others read, as when each is opened in turn.
    """
    path = tmp_path / 'crc'
    write_imu_bag(path, _samples(20000), storage='mcap')
    raw = bytearray(next(path.glob('*.mcap')).read_bytes())
    scan = McapScan(next(path.glob('*.mcap')))
    scan.run()
    assert len(scan.chunk_offsets) >= 4 and not scan.warnings
    third = scan.chunk_offsets[2]
    raw[third + 200] ^= 0xFF              # inside the third chunk's records
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(bytes(raw))
    outcomes = []
    for ahead in (mcap_scan.AHEAD, 0):
        monkeypatch.setattr(mcap_scan, 'AHEAD', ahead)
        scan = McapScan(bad)
        scan.run()
        outcomes.append((scan.warnings, scan.collectors['/imu/data_raw'].result()))
    (w_ahead, (t_ahead, d_ahead)), (w_turn, (t_turn, d_turn)) = outcomes
    assert w_ahead == w_turn and len(w_ahead) == 1
    assert f'corrupt chunk at byte {third} skipped (chunk checksum mismatch)' in w_ahead[0]
    assert np.array_equal(t_ahead, t_turn) and np.array_equal(d_ahead, d_turn)


_FRESH = """
import json, sys
from imu_allan.formats import collector, mcap_scan
from imu_allan.formats.bag_reader import read_bag
calls = []
prefault = collector.Collector.prefault
collector.Collector.prefault = lambda self: calls.append(len(self._t)) or prefault(self)
mcap_scan.COMPILED_MIN_BYTES = 0
assert 'numba' not in sys.modules
r = read_bag(sys.argv[1])
print(json.dumps([calls, r.t.tolist(), r.data.tolist(), r.warnings]))
"""


def test_arrays_written_ahead_while_numba_is_imported(tmp_path):
    """
    In a process without numba yet, the topic's arrays are written to on a thread meanwhile.

    The walk then fills them: the same numbers as a read in this process (numba loaded).
    """
    path = tmp_path / 'fresh'
    write_imu_bag(path, _samples(20000), storage='mcap')
    out = subprocess.run([sys.executable, '-c', _FRESH, str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    calls, t, data, warnings = json.loads(out.stdout)
    assert calls == [20000]                 # the summary's count: exactly the topic's messages
    r = read_bag(path)
    assert np.array_equal(np.array(t), r.t) and np.array_equal(np.array(data), r.data)
    assert warnings == r.warnings == []
