"""
Damaged sqlite3 structure: when SQLite itself can tell the file is damaged, so does the report.

sqlite3 storage has no checksums, so a flipped byte inside a message's values cannot be seen
by anyone; but a flipped timestamp, row id, cell pointer or payload size breaks the B-tree's
own consistency, which ``PRAGMA integrity_check`` reports.  The page walk checks the same
facts it can reach cheaply: every record fills the payload its cell declares, and the rows
of the message table (every topic) equal the entries of its timestamp index (a digest and a
count, :meth:`SqlitePages.index_problem`).  Each copy of a real bag gets 20 seeded bit flips;
the property: whenever integrity_check reports damage and our samples changed, the reader
warns.  Both walks (numpy and compiled) run on every copy.

SQLite also sees damage that leaves every row intact: a page's fragmented-bytes counter,
freeblock chain or content start that no longer account for its free space ("Fragmentation
of ... reported as ..."), and schema SQL text it cannot parse ("malformed database schema").
The walk checks those too, at no extra pass: each table-leaf page's cells, freeblocks and
fragment count must fill its content area exactly (:meth:`SqlitePages.space_failures`, in
both walks, and the small tables' pages with their records and rowid order), and the
schema is checked as SQLite reads it (:meth:`SqlitePages.schema_problem`): row types, root
pages (in the file, of the right kind, one per object, not page 1), the CREATE statements
replayed into an in-memory database to the same objects, the messages row layout, and the
small tables' rows against their columns.  Such a copy gives the same samples with a
warning (or, where the schema no longer leads to the rows, one clean line).
"""

import sqlite3

from formats.flip_cases import flipped
from imu_allan.errors import InputError
from imu_allan.formats import imu_cdr, scan_common, sqlite_pages
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.collector import Collector
from imu_allan.formats.samples import Samples
from imu_allan.formats.sqlite_pages import SqlitePages
import numpy as np
import pytest

N = 3000
COPIES = 60


def _samples():
    rng = np.random.default_rng(0)
    return Samples(t=1.7e9 + np.arange(N) / 100.0, data=rng.normal(0.0, 1e-3, (N, 6)))


def integrity(path):
    """Return SQLite's own verdict: [] when intact, else its integrity_check lines or error."""
    try:
        con = sqlite3.connect(f'file:{path}?mode=ro', uri=True)
        try:
            lines = [row[0] for row in con.execute('PRAGMA integrity_check')]
        finally:
            con.close()
    except (sqlite3.Error, UnicodeDecodeError) as err:  # (a message quoting damaged text)
        return [str(err)]
    return [] if lines == ['ok'] else lines


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """Return the bytes of a valid sqlite3 bag and its samples as read."""
    folder = write_imu_bag(tmp_path_factory.mktemp('ok') / 'bag', _samples(), storage='sqlite3')
    src = next(folder.glob('*.db3'))
    assert integrity(src) == []
    return src.read_bytes(), read_bag(src)


def test_intact_bag_rows_match_the_index(bag, tmp_path):
    """The check holds on an intact bag (no false alarm), in both walks."""
    raw, ref = bag
    path = tmp_path / 'ok.db3'
    path.write_bytes(raw)
    assert not ref.warnings
    pages = SqlitePages(path)
    try:
        roots = pages.schema()
        assert pages.indexes.get('timestamp_idx', ('', 0))[0] == 'messages'
        coll = Collector(False, imu_cdr.deserialize)
        pages.read_messages(roots['messages'], [1], coll)
        assert int(pages.digest[1]) == N and pages.index_problem() == ''
    finally:
        pages.close()


@pytest.mark.parametrize('walk', ['numpy', 'compiled'])
def test_damage_sqlite_can_see_is_reported(bag, tmp_path, walk, monkeypatch):
    """Seeded flips: integrity_check damage and changed samples always come with a warning."""
    raw, ref = bag
    if walk == 'compiled':
        if scan_common.compiled_walks(True) is None:
            pytest.skip('numba walk not available')
        monkeypatch.setattr(sqlite_pages, 'COMPILED_MIN_PAGES', 0)
    counts = {'same': 0, 'warned': 0, 'refused': 0, 'unseen': 0}
    for seed in range(COPIES):
        path = tmp_path / f'damaged{seed}.db3'
        path.write_bytes(flipped(raw, seed))
        damage = integrity(path)
        try:
            got = read_bag(path)
        except InputError as exc:
            assert '\n' not in str(exc)
            counts['refused'] += 1
            continue
        same = (got.t.shape == ref.t.shape and np.array_equal(got.t, ref.t)
                and np.array_equal(got.data, ref.data))
        if same:
            counts['same'] += 1
        elif got.warnings:
            counts['warned'] += 1
        else:
            # A changed value inside a message: no container can see it (no checksums).
            assert not damage, (seed, damage[:3])
            counts['unseen'] += 1
    # Most copies carry damage SQLite sees (20 flips over 290 pages): the check is exercised.
    assert counts['warned'] >= COPIES // 2, counts


def test_compiled_index_digest_equals_the_numpy_one(bag, tmp_path, monkeypatch):
    """The compiled level walk gives the numpy digest (or the same None) on intact and damaged."""
    if scan_common.compiled_walks(True) is None:
        pytest.skip('numba walk not available')
    raw, _ = bag
    for seed in range(-1, 30):
        path = tmp_path / f'c{seed}.db3'
        path.write_bytes(raw if seed < 0 else flipped(raw, seed, flips=40))
        got = []
        for threshold in (10**9, 0):   # numpy walk, then the compiled one
            monkeypatch.setattr(sqlite_pages, 'COMPILED_MIN_PAGES', threshold)
            pages = SqlitePages(path)
            try:
                pages.schema()
                root = pages.indexes.get('timestamp_idx', ('', None))[1]
                got.append(None if root is None else pages.index_digest(root))
            except Exception as exc:  # noqa: B902 - the schema page itself may be damaged
                got.append(type(exc).__name__)
            finally:
                pages.close()
        assert got[0] == got[1], (seed, got)


def _walk(walk, monkeypatch):
    if walk == 'compiled':
        if scan_common.compiled_walks(True) is None:
            pytest.skip('numba walk not available')
        monkeypatch.setattr(sqlite_pages, 'COMPILED_MIN_PAGES', 0)
    else:
        monkeypatch.setattr(sqlite_pages, 'COMPILED_MIN_PAGES', 10**9)


def _leaf_pages(path):
    pages = SqlitePages(path)
    try:
        return pages.page_size, pages.leaf_pages(pages.schema()['messages'])
    finally:
        pages.close()


@pytest.mark.parametrize('walk', ['numpy', 'compiled'])
def test_free_space_damage_gives_the_same_samples_and_a_warning(bag, tmp_path, walk,
                                                                monkeypatch):
    """
    A flipped bit in a message page's free-space fields: SQLite sees it, so does the report.

    The fields (first freeblock, content start, fragmented bytes: header bytes 1-2, 5-6, 7)
    do not place any row, so the samples stay the same; 24 seeded (page, field, bit) flips,
    each checked to be damage SQLite's integrity_check reports.
    """
    _walk(walk, monkeypatch)
    raw, ref = bag
    path = tmp_path / 'ok.db3'
    path.write_bytes(raw)
    ps, leaves = _leaf_pages(path)
    rng = np.random.default_rng(11)
    seen = 0
    for k in range(24):
        page = int(rng.choice(leaves))
        at = (page - 1) * ps + int(rng.choice([1, 2, 5, 6, 7]))
        buf = bytearray(raw)
        buf[at] ^= 1 << int(rng.integers(0, 8))
        path = tmp_path / f'space{k}.db3'
        path.write_bytes(bytes(buf))
        if not integrity(path):
            continue  # (a flip SQLite accepts too: nothing to report)
        seen += 1
        got = read_bag(path)
        assert np.array_equal(got.t, ref.t) and np.array_equal(got.data, ref.data)
        assert any('damaged sqlite3 file' in w for w in got.warnings), (k, page, at)
    assert seen >= 12


@pytest.mark.parametrize('statement', [b'CREATE TABLE messages', b'CREATE INDEX timestamp_idx',
                                       b'CREATE TABLE topics'])
def test_schema_sql_damage_is_reported(bag, tmp_path, statement):
    """
    Flipped bits in a schema's CREATE statement: what SQLite calls damaged, the reader too.

    Whenever SQLite calls the file damaged (or cannot open it), the reader warns or refuses
    in one line.  Every byte of the statement up to its first ')' and 60 bytes beyond (the
    next schema row's cell), one seeded bit each.
    """
    raw, ref = bag
    start = raw.index(statement)
    rng = np.random.default_rng(5)
    counts = {'warned': 0, 'refused': 0, 'accepted': 0}
    for k in range(raw.index(b')', start) + 61 - start):
        buf = bytearray(raw)
        buf[start + k] ^= 1 << int(rng.integers(0, 8))
        path = tmp_path / f'sql{k}.db3'
        path.write_bytes(bytes(buf))
        damage = integrity(path)
        try:
            got = read_bag(path)
        except InputError as exc:
            assert '\n' not in str(exc)
            counts['refused'] += 1
            continue
        if any('damaged sqlite3 file' in w for w in got.warnings):
            counts['warned'] += 1
        else:
            assert not damage, (k, damage[:2])
            counts['accepted'] += 1
    assert counts['warned'] + counts['refused'] >= 20, counts
