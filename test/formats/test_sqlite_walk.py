"""
The compiled sqlite3 page walk (bag_kernels.sqlite_walk) against the numpy walk it replaces.

Each bag is read twice through ``read_bag``: once with the numpy walk (``SqlitePages._batch``,
the readable reference) and once with the compiled walk forced on (its size threshold set to
0); stamps, values, frame id and warnings (which carry the counts of damaged messages and lost
pages) must be identical, and the compiled walk must have read batches itself.  The bags come
from the generators of test_bags.py plus damage made here at known cells.
"""

import json
import subprocess
import sys

from formats.test_bags import (
    _samples,
    bad_nanosecond_bag,
    big_message_bag,
    damaged_copies,
    mixed_frame_bag,
)
from imu_allan.errors import InputError
from imu_allan.formats import sqlite_pages
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.sqlite_pages import SqlitePages
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

JAZZY = get_typestore(Stores.ROS2_JAZZY)


def _outcome(path, topic):
    """Return what read_bag gives: ('samples', t, data, frame id, warnings) or ('error', text)."""
    try:
        r = read_bag(path, topic=topic)
    except InputError as err:
        return ('error', str(err))
    return ('samples', r.t, r.data, r.frame_id, r.warnings)


def _same_outcome(a, b):
    if a[0] != b[0] or len(a) != len(b):
        return False
    return all(np.array_equal(x, y, equal_nan=True) if isinstance(x, np.ndarray) else x == y
               for x, y in zip(a, b))


@pytest.fixture
def both(monkeypatch):
    """Return read(path, topic) -> (numpy walk outcome, compiled walk outcome, batches walked)."""
    walked = []
    plain = SqlitePages._walk

    def counting(self, kernel, pages, wanted, coll):
        done = plain(self, kernel, pages, wanted, coll)
        walked.append(done)
        return done
    monkeypatch.setattr(SqlitePages, '_walk', counting)

    def read(path, topic=None):
        with monkeypatch.context() as m:
            m.setattr(sqlite_pages, 'compiled_walk', lambda npages: None)
            ref = _outcome(path, topic)
        assert not walked
        with monkeypatch.context() as m:
            m.setattr(sqlite_pages, 'COMPILED_MIN_PAGES', 0)
            fast = _outcome(path, topic)
        n = sum(walked)
        walked.clear()
        return ref, fast, n
    return read


def _db(path):
    return next(path.glob('*.db3'))


def test_mixed_frame_ids_and_other_topics(tmp_path, both):
    """Seven CDR paddings interleaved on one topic, another Imu topic beside it: both topics."""
    path = mixed_frame_bag(tmp_path, 'sqlite3')
    for topic, n in (('/imu/mixed', 140), ('/imu/base', 300)):
        ref, fast, walked = both(path, topic)
        assert ref[0] == 'samples' and ref[1].shape == (n,)
        assert walked >= 1 and _same_outcome(ref, fast), topic
    assert fast[3] == 'imu_link' and ref[3] == 'imu_link'


def test_impossible_nanoseconds_counted_the_same(tmp_path, both):
    """The three messages with nanosec >= 1e9 are dropped and counted by both walks."""
    path, s, bad = bad_nanosecond_bag(tmp_path, 'sqlite3')
    ref, fast, walked = both(path, '/imu/n')
    assert walked >= 1 and _same_outcome(ref, fast)
    assert fast[1].shape == (117,)
    assert any('3 damaged message(s)' in w for w in fast[4]), fast[4]


def test_overflow_pages_of_other_topics_and_of_imu_messages(tmp_path, both):
    """
    Cells on overflow pages: large Strings between Imu messages, and Imu messages of 5 kB.

    The long Imu messages (a 5000-byte frame id, every 7th message of their topic) go through
    the slow cell path in both walks and are decoded by the generic deserializer.
    """
    path, s = big_message_bag(tmp_path, 'sqlite3')
    ref, fast, walked = both(path)
    assert walked >= 1 and _same_outcome(ref, fast)
    assert np.array_equal(fast[2], s.data)
    from imu_allan.formats.imu_cdr import encode_imu
    s = _samples(400, seed=5)
    msgs = []
    for i in range(400):
        fid = 'f' * 5000 if i % 7 == 3 else 'imu'
        rows, stamps = encode_imu(s.t[i:i + 1], s.data[i:i + 1], fid)
        msgs.append((int(stamps[0]), JAZZY.deserialize_cdr(rows[0].tobytes(),
                                                           'sensor_msgs/msg/Imu')))
    long_path = tmp_path / 'long'
    write_imu_bag(long_path, _samples(50), topic='/imu/base', storage='sqlite3',
                  extra_topics={'/imu/long': ('sensor_msgs/msg/Imu', msgs)})
    ref, fast, walked = both(long_path, '/imu/long')
    assert walked >= 1 and _same_outcome(ref, fast)
    assert np.array_equal(fast[2], s.data) and fast[3] == 'imu'


def test_negative_seconds(tmp_path, both):
    """Stamps before 1970 (int32 sec < 0) decode the same."""
    path = tmp_path / 'neg'
    s = _samples(500, t0=-1000.25)
    write_imu_bag(path, s, storage='sqlite3')
    ref, fast, walked = both(path)
    assert walked >= 1 and _same_outcome(ref, fast)
    assert np.max(np.abs(fast[1] - s.t)) < 1e-6


def _cells(path):
    """Return (page size, [(page offset, [cell offsets])]) of the messages table's leaves."""
    pg = SqlitePages(path)
    try:
        root = pg.schema()['messages']
        out = []
        for no in pg.leaf_pages(root):
            base, hdr = pg._page(no)
            ncell = int(pg.u8[hdr + 3]) * 256 + int(pg.u8[hdr + 4])
            out.append((base, hdr, [base + int(p) for p in pg._ptrs(hdr, ncell, 0)]))
        return pg.page_size, out
    finally:
        pg.close()


def test_damaged_cells_and_pages(tmp_path, both):
    """
    Damage at known places gives the same samples, counts and warnings on both walks.

    In a 3000-message bag (about 260 leaf pages): a blob turned big-endian CDR (the generic
    deserializer takes it), a blob's serial type made text (a cell the slow path refuses), a
    cell pointer past its page (a lost page), a payload size varint made 9 bytes long, a page
    whose type byte is no table leaf, and a page whose cell count overflows the page.
    """
    path = tmp_path / 'd'
    s = _samples(3000)
    write_imu_bag(path, s, storage='sqlite3')
    db = _db(path)
    ps, leaves = _cells(db)
    raw = bytearray(db.read_bytes())
    rng = np.random.default_rng(7)
    picks = rng.choice(np.arange(1, len(leaves) - 1), 6, replace=False)
    # 1. a blob whose encapsulation says big-endian: bytes 00 01 -> 00 00
    base, hdr, cells = leaves[picks[0]]
    blob = raw.find(b'\x00\x01\x00\x00', cells[2])
    assert 0 < blob - cells[2] < 40
    raw[blob + 1] = 0
    # 2. the blob's serial type made odd (text). Record header: size 6, NULL id, topic id 1
    #    (serial type 9), 8-byte timestamp (6), the blob's 2-byte serial type.
    base, hdr, cells = leaves[picks[1]]
    head = raw.find(b'\x06\x00\x09\x06', cells[1])
    assert 0 < head - cells[1] < 12
    raw[head + 5] |= 1
    # 3. a cell pointer past its page
    base, hdr, cells = leaves[picks[2]]
    raw[hdr + 8 + 2 * 3:hdr + 8 + 2 * 3 + 2] = (ps - 2).to_bytes(2, 'big')
    # 4. a payload size varint made 9 bytes long
    base, hdr, cells = leaves[picks[3]]
    raw[cells[4]:cells[4] + 9] = b'\xff' * 9
    # 5. a page that is no table leaf (0x0A: an index leaf)
    raw[leaves[picks[4]][1]] = 0x0A
    # 6. a cell count whose pointers would not fit in the page
    hdr = leaves[picks[5]][1]
    raw[hdr + 3:hdr + 5] = (ps // 2).to_bytes(2, 'big')
    db.write_bytes(bytes(raw))
    ref, fast, walked = both(path)
    assert walked >= 1 and _same_outcome(ref, fast)
    assert 2500 < fast[1].shape[0] < 3000
    assert any('page(s) of the message table unreadable' in w for w in fast[4]), fast[4]
    # Nothing garbled: every sample read is one written (the big-endian one is dropped).
    idx = np.searchsorted(s.t, fast[1])
    assert np.array_equal(s.data[idx], fast[2])


def test_cut_file(tmp_path, both):
    """A file cut in the middle: every table-leaf page tried, the intact ones read, the same."""
    path = tmp_path / 'c'
    write_imu_bag(path, _samples(6000), storage='sqlite3')
    raw = _db(path).read_bytes()
    cut = tmp_path / 'cut.db3'
    cut.write_bytes(raw[:len(raw) // 2 + 1234])
    ref, fast, walked = both(cut)
    assert walked >= 1 and _same_outcome(ref, fast)
    assert 1000 < fast[1].shape[0] < 6000


def test_random_damage_same_outcome(tmp_path, both):
    """
    Seeded random overwrites (1-63 bytes at 1-3 places) or cuts: the same outcome, always.

    12 variants of an 8000-message bag (about 700 leaf pages: two batches of the walk).
    """
    path = tmp_path / 'good'
    write_imu_bag(path, _samples(8000), storage='sqlite3')
    raw = _db(path).read_bytes()
    kinds = set()
    for k, data in enumerate(damaged_copies(raw, seed=23, count=12, first=4096)):
        bad = tmp_path / f'bad{k}.db3'
        bad.write_bytes(data)
        ref, fast, walked = both(bad)
        assert _same_outcome(ref, fast), k
        kinds.add(ref[0])
    assert 'samples' in kinds


_NO_NUMBA = """
import json, sys
sys.modules['numba'] = None
from imu_allan.formats import sqlite_pages
from imu_allan.formats.bag_reader import read_bag
sqlite_pages.COMPILED_MIN_PAGES = 0
r = read_bag(sys.argv[1])
print(json.dumps([sqlite_pages.compiled_walk(10 ** 9) is None, r.t.tolist(), r.data.tolist(),
                  r.warnings]))
"""


def test_without_numba_the_numpy_walk_reads_the_same(tmp_path):
    """
    Without numba (optional) the numpy walk reads: the same numbers, and no error.

    The child blocks ``import numba`` as a platform without it would; this process reads the
    same bag with the compiled walk.
    """
    path, s = big_message_bag(tmp_path, 'sqlite3')
    out = subprocess.run([sys.executable, '-c', _NO_NUMBA, str(path)], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    none, t, data, warnings = json.loads(out.stdout)
    assert none
    assert sqlite_pages.compiled_walk(10 ** 9) is not None
    r = read_bag(path)
    assert np.array_equal(np.array(t), r.t) and np.array_equal(np.array(data), r.data)
    assert warnings == r.warnings


_SMALL_READ = """
import sys
from imu_allan.formats.bag_reader import read_bag
r = read_bag(sys.argv[1], topic='/imu/mixed')
print(r.n, 'numba' in sys.modules)
"""


def test_small_file_does_not_import_numba(tmp_path):
    """
    A file below COMPILED_MIN_PAGES is read by the numpy walk without importing numba.

    Importing numba and loading the walk costs about 1 s, more than such a file takes to read.
    """
    path = mixed_frame_bag(tmp_path, 'sqlite3')
    out = subprocess.run([sys.executable, '-c', _SMALL_READ, str(path / 'mixed.db3')],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['140', 'False'], out.stdout


def test_no_compiled_walk_where_it_cannot_be_cached(monkeypatch):
    """Without a cache folder for numba the walk would compile in every process: numpy walk."""
    from imu_allan.formats import bag_kernels
    assert sqlite_pages.compiled_walk(10 ** 9) is bag_kernels
    monkeypatch.setattr(bag_kernels, 'CACHED', False)
    assert sqlite_pages.compiled_walk(10 ** 9) is None
