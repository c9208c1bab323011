"""
Read ``sensor_msgs/msg/Imu`` samples from rosbag2 (sqlite3, MCAP) and ROS 1 bags.

Two paths give identical numbers:

* the generic path deserializes every message with ``rosbags`` and converts it with the one
  message -> numpy adapter (:mod:`imu_allan.formats.imu_adapter`); about 120-150 k messages/s;
* the fast path decodes the fixed layout of ``sensor_msgs/Imu`` in bulk with numpy
  (:mod:`imu_allan.formats.imu_cdr`).

The fast path walks the storage itself (one raw message at a time from rosbags would cap it
below 1 M messages/s): :mod:`.mcap_scan`, :mod:`.sqlite_pages` (SQL queries remain the
fallback: write-ahead log, odd layouts) and :mod:`.ros1_scan`.  This module opens the bag,
picks the topic and dispatches to those readers.

Damaged input raises :class:`~imu_allan.errors.InputError`, or, when part of it is readable,
returns what was read with a line in ``Samples.warnings`` saying what was skipped (what each
reader recovers: its module docstring).  rosbags refuses such files; the generic path then
uses the same direct readers with per-message deserialization.

``t`` is the header stamp (``sec + nanosec * 1e-9`` s) in bag order (receive time order).
"""

from pathlib import Path
import sqlite3
import struct

import numpy as np

from .collector import Collector, damaged_warning
from .imu_adapter import imu_to_row
from .imu_cdr import deserialize, IMU_TYPES, MIN_IMU_BYTES, valid_stamp
from .mcap_scan import MCAP_MAGIC, McapScan
from .ros1_scan import read_ros1_scan, ROS1_MAGIC, Ros1Scan
from .samples import Samples
from .scan_common import choose_topic, one_line
from .sqlite_pages import SQLITE_MAGIC, SqlitePages, Unsupported
from ..core.units import AXES
from ..errors import InputError

#: The first bytes of each storage file.
_MAGIC = {'mcap': MCAP_MAGIC, 'sqlite3': SQLITE_MAGIC, 'ros1': ROS1_MAGIC}


def bag_kind(path):
    """Classify a path: ('ros1'|'mcap'|'sqlite3'|'dir', storage files) or raise InputError."""
    p = Path(path)
    if not p.exists():
        raise InputError(path, 'no such file or directory')
    if p.is_dir():
        meta = p / 'metadata.yaml'
        if meta.exists():
            return 'dir', p
        files = sorted(x for x in p.iterdir() if x.suffix in ('.mcap', '.db3'))
        if len(files) == 1:
            return bag_kind(files[0])
        raise InputError(path, 'not a rosbag2 folder (no metadata.yaml)')
    try:
        with open(p, 'rb') as f:
            head = f.read(16)
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    if not head:
        raise InputError(path, 'empty file, not a bag')
    kind = next((k for k, magic in _MAGIC.items() if head.startswith(magic)), None)
    if kind is None:
        raise InputError(path, 'not a bag (no ROS 1, MCAP or sqlite3 signature)')
    return kind, p


def _dir_storage(p):
    """Return (storage id, [files], compressed, note) of a rosbag2 folder (its metadata.yaml)."""
    import yaml
    try:
        meta = yaml.safe_load((p / 'metadata.yaml').read_text())
        info = meta['rosbag2_bagfile_information']
        storage = info.get('storage_identifier', '')
        files = [p / Path(x).name for x in info['relative_file_paths']]
        compressed = bool(info.get('compression_mode')) and \
            str(info.get('compression_mode')).lower() != 'none'
    except Exception as err:
        raise InputError(p, f'unreadable metadata.yaml ({type(err).__name__})') from None
    missing = [x.name for x in files if not x.exists()]
    if missing:
        raise InputError(p, f'storage file missing: {", ".join(missing)}')
    note = None
    signed = {_signature(x) for x in files} - {None}
    if len(signed) == 1 and signed != {storage}:
        # The files' own signature is the fact; metadata.yaml is a description of it.
        note = (f'metadata.yaml names storage {str(storage)[:20]!r} but the files are '
                f'{signed.pop()}: read as the files say')
        storage = _signature(files[0])
    return storage, files, compressed, note


def _signature(path):
    """Storage named by a file's first bytes ('mcap', 'sqlite3'), or None."""
    try:
        with open(path, 'rb') as f:
            head = f.read(16)
    except OSError:
        return None
    return next((k for k in ('mcap', 'sqlite3') if head.startswith(_MAGIC[k])), None)


def any_reader(paths, where):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import get_typestore, Stores
    try:
        reader = AnyReader([Path(x) for x in paths],
                           default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as err:
        raise InputError(where, f'cannot open bag: {one_line(err)}') from None
    return reader


def bag_topics(path):
    """
    Return ``{topic: (type, message count)}`` of a bag (any supported form).

    Uses the bag's index through rosbags; a damaged MCAP or ROS 1 file is scanned instead
    (counting the readable messages).
    """
    kind, p = bag_kind(path)
    try:
        reader = any_reader([p], path)
    except InputError:
        scan = None
        if kind == 'mcap' or (kind == 'dir' and _dir_storage(p)[0] == 'mcap'):
            scan = McapScan(str(_storage_files(p, kind, 'mcap')[0]), collect=False)
            names = scan.channels
        elif kind == 'ros1':
            scan = Ros1Scan(p, collect=False)
            names = scan.conns
        if scan is None:
            raise
        scan.run()
        return {ch[0]: (ch[1], scan.counts.get(cid, 0)) for cid, ch in names.items()}
    try:
        return _reader_topics(reader)
    finally:
        reader.close()


def _reader_topics(reader):
    """Return ``{topic: (type, message count)}`` of a rosbags reader's connections."""
    out = {}
    for c in reader.connections:
        typ, n = out.get(c.topic, (c.msgtype, 0))
        out[c.topic] = (typ, n + c.msgcount)
    return out


def list_imu_topics(path):
    """Return the names of the ``sensor_msgs/Imu`` topics of a bag, in bag order."""
    return [t for t, (typ, _) in bag_topics(path).items() if typ in IMU_TYPES]


def read_bag(path, topic=None, fast=True):
    """
    Read the Imu samples of one topic of a bag: ``t`` header stamps in s, ``data`` rad/s, m/s^2.

    ``path``: a rosbag2 folder, a bare ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``;
    ``topic``: by default the only ``sensor_msgs/Imu`` topic; ``fast``: the bulk numpy decoder
    (False: the generic ``rosbags`` deserializer, same numbers).  Raises :class:`InputError`
    for a missing path, not a bag, an unreadable bag, no or several Imu topics, a wrong type
    or an empty topic.
    """
    where = str(path)
    kind, p = bag_kind(path)
    checks = {}
    storage, note = kind, None
    if kind == 'dir':
        storage, files, compressed, note = _dir_storage(p)
        if storage == 'mcap' and not compressed and fast:
            res = _read_mcap_files(where, files, topic, checks=checks)
        elif storage == 'sqlite3' and not compressed and fast:
            res = _read_sqlite_files(where, files, topic, checks=checks)
        else:
            res = _read_generic(where, p, topic)
    elif kind == 'mcap' and fast:
        res = _read_mcap_files(where, [p], topic, checks=checks)
    elif kind == 'sqlite3' and fast:
        res = _read_sqlite_files(where, [p], topic, checks=checks)
    elif kind == 'ros1' and fast:
        res = read_ros1_scan(where, p, topic) or _read_ros1_fast(where, p, topic)
    else:
        res = _read_generic(where, p, topic)
    chosen, t, data, warnings, frame_id = res
    warnings = ([note] if note else []) + warnings
    if t.shape[0] == 0:
        extra = f' ({"; ".join(warnings)})' if warnings else ''
        raise InputError(path, f'topic {chosen} has no messages{extra}')
    integrity = INTEGRITY.get(storage, '')
    if checks.get('chunks_without_crc'):
        integrity = (f'{checks["chunks_without_crc"]} MCAP chunk(s) carry no CRC-32 (their writer '
                     'stored none): their values could not be verified')
    return Samples(t=t, data=data, axes=AXES, source=f'{where}:{chosen}', warnings=warnings,
                   integrity=integrity, topic=chosen, frame_id=frame_id,
                   topic_types=checks.get('topic_types'))


#: What a reader can verify in each storage (said in the report, so a reader of the report
#: knows which damage could have gone unnoticed).
INTEGRITY = {
    'mcap': 'MCAP chunks checked against their CRC-32; message bytes outside chunks cannot be '
            'verified',
    'sqlite3': 'sqlite3 storage has no checksums: a damaged value or stamp inside a message '
               'cannot be detected, only non-physical values and disordered stamps',
    'ros1': 'ROS 1 bags have no checksums: decompression catches most damage in a compressed '
            'chunk, but a damaged value inside a message cannot be detected',
}


def _read_generic(where, p, topic):
    """Read through ``AnyReader`` and the per-message deserializer (the reference path)."""
    kind = bag_kind(p)[0]
    try:
        reader = any_reader([p], where)
    except InputError:
        # rosbags cannot open damaged files (no MCAP footer, no ROS 1 index, malformed SQLite):
        # read what is left with the direct readers, deserializing message by message.
        mcap = _storage_files(p, kind, 'mcap')
        if mcap:
            return _read_mcap_files(where, mcap, topic, force_generic=True)
        if kind == 'ros1':
            # rosbags needs the index at the end: read the chunks of a cut bag one by one.
            res = read_ros1_scan(where, p, topic, force_generic=True)
            if res is None:
                raise
            return res
        files = _storage_files(p, kind, 'sqlite3')
        if not files:
            raise
        return _read_sqlite_files(where, files, topic, force_generic=True)
    warnings = []
    try:
        chosen, conns = _chosen_connections(reader, where, topic)
        stamps, rows = [], []
        bad = 0
        frame_id = ''
        try:
            for conn, _, raw in reader.messages(connections=conns):
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                    s, row = imu_to_row(msg)
                except Exception:  # one garbled message: skip it, as the fast path does
                    bad += 1
                    continue
                if not valid_stamp(msg):
                    bad += 1
                    continue
                if not stamps:
                    frame_id = str(msg.header.frame_id)
                stamps.append(s)
                rows.append(row)
        except Exception as err:
            mcap = _storage_files(p, kind, 'mcap')
            if mcap:
                # A corrupt chunk stops rosbags; the scanner skips just that chunk.
                reader.close()
                reader = None
                return _read_mcap_files(where, mcap, topic, force_generic=True)
            if not stamps:
                raise InputError(where, f'cannot read messages: {one_line(err)}') from None
            warnings.append(f'read stopped after {len(stamps)} messages: {one_line(err)}')
        if bad:
            warnings.append(damaged_warning(bad))
    finally:
        if reader is not None:
            reader.close()
    t = np.asarray(stamps, dtype=np.float64)
    data = np.asarray(rows, dtype=np.float64).reshape(len(rows), 6)
    return chosen, t, data, warnings, frame_id


def _storage_files(p, kind, storage):
    """Return the uncompressed ``storage`` ('mcap', 'sqlite3') files of a bag, or []."""
    if kind == storage:
        return [p]
    if kind == 'dir':
        found, files, compressed = _dir_storage(p)[:3]
        if found == storage and not compressed:
            return files
    return []


def _topic_types(checks, topics):
    """
    Note ``{topic: message type}`` of the bag in ``checks`` (when given).

    Handed on as ``Samples.topic_types``, so that ``analyze`` opens the bag a second time
    (with rosbags, which on sqlite3 counts every row: 2.8 s of CPU on a 10 h bag) only when
    it holds a topic that it reads beside the Imu (the temperature).
    """
    if checks is not None:
        checks['topic_types'] = {name: typ for name, (typ, _) in topics.items()}


def _choose_mcap_topic(where, scans, topics, topic):
    """Pick the topic of scanned MCAP files; a damaged file with no Imu data is an error."""
    warnings = [w for scan in scans for w in scan.warnings]
    if warnings and not any(typ in IMU_TYPES for typ, _ in topics.values()):
        raise InputError(where, f'damaged MCAP, no Imu data readable ({warnings[0]})')
    return choose_topic(where, topics, topic)


def _join(ts, ds):
    """Concatenate per-file results (no copy for the usual single file)."""
    if len(ts) == 1:
        return ts[0], ds[0]
    return np.concatenate(ts), np.concatenate(ds)


def _read_mcap_files(where, files, topic, force_generic=False, checks=None):
    """
    Fast path for MCAP storage: scan every file, bulk-decode the chosen topic.

    ``checks`` (a dict) receives ``chunks_without_crc``, the chunks that could not be verified,
    and ``topic_types`` (:func:`_topic_types`).
    """
    scans = []
    for f in files:
        scan = McapScan(str(f), topic, force_generic=force_generic)
        try:
            scan.run()
        except InputError as err:
            raise InputError(where, err.problem) from None
        scans.append(scan)
    topics = {}
    for scan in scans:
        for cid, ch in scan.channels.items():
            typ, n = topics.get(ch[0], (ch[1], 0))
            topics[ch[0]] = (typ, n + scan.counts.get(cid, 0))
    chosen = _choose_mcap_topic(where, scans, topics, topic)
    _topic_types(checks, topics)
    encodings = {ch[2] for scan in scans for ch in scan.channels.values() if ch[0] == chosen}
    if encodings - {'cdr'}:
        raise InputError(where, f'topic {chosen} uses message encoding '
                                f'{", ".join(sorted(encodings - {"cdr"}))}; only CDR is supported')
    ts, ds, warnings, frames = [], [], [], []
    for scan in scans:
        if chosen in scan.collectors:
            t, d = scan.collectors[chosen].result()
            ts.append(t)
            ds.append(d)
            warnings += scan.collectors[chosen].warnings()
            frames.append(scan.collectors[chosen].frame_id)
        warnings += scan.warnings
        if checks is not None:
            checks['chunks_without_crc'] = (checks.get('chunks_without_crc', 0)
                                            + scan.chunks_without_crc)
    if not ts:
        return chosen, np.zeros(0), np.zeros((0, 6)), warnings, ''
    return chosen, *_join(ts, ds), warnings, frames[0]


def _read_sqlite_files(where, files, topic, force_generic=False, checks=None):
    """
    Fast path for sqlite3 storage: walk the messages B-tree of each file, decode in bulk.

    Falls back to SQL queries for files the page reader does not handle (write-ahead log
    present, unusual record layout).  ``checks`` (a dict) receives ``topic_types``.
    """
    opened = []
    try:
        topics = {}
        for f in files:
            src = _SqliteSource(where, f)
            opened.append(src)
            for _tid, name, typ in src.topic_rows:
                topics.setdefault(name, (typ, 0))
        if not topics and any(src.warnings for src in opened):
            raise InputError(where, f'damaged sqlite3 bag, no topic readable '
                                    f'({opened[0].warnings[0]})')
        chosen = choose_topic(where, topics, topic)
        _topic_types(checks, topics)
        ts, ds, warnings, frames = [], [], [], []
        for src in opened:
            ids = [tid for tid, name, _ in src.topic_rows if name == chosen]
            coll = Collector(False, deserialize, force_generic,
                             capacity=src.path.stat().st_size // MIN_IMU_BYTES)
            if ids:
                src.read(ids, coll)
            t, d = coll.result()
            warnings += src.warnings + coll.warnings()
            ts.append(t)
            ds.append(d)
            frames.append(coll.frame_id)
    finally:
        for src in opened:
            src.close()
    return chosen, *_join(ts, ds), warnings, next((f for f in frames if f), '')


class _SqliteSource:
    """One sqlite3 storage file, read by the page reader or, failing that, by SQL."""

    def __init__(self, where, path):
        self.where = where
        self.path = Path(path)
        self.warnings = []
        self.pages = None
        self.con = None
        wal = Path(f'{path}-wal')
        if not (wal.exists() and wal.stat().st_size):
            try:
                self.pages = SqlitePages(path)
                roots = self.pages.schema()
                if 'messages' not in roots or 'topics' not in roots:
                    raise Unsupported('no rosbag2 tables')
                self.roots = roots
                self.topic_rows = self.pages.topics(roots['topics'])
                return
            except (Unsupported, IndexError, struct.error, ValueError, TypeError):
                if self.pages is not None:
                    self.pages.close()
                self.pages = None
        self._open_sql()

    def _open_sql(self):
        uri = f'file:{self.path}?mode=ro'
        try:
            self.con = sqlite3.connect(uri, uri=True)
            self.topic_rows = self.con.execute('SELECT id, name, type FROM topics').fetchall()
        except sqlite3.Error as err:
            raise InputError(self.where, f'not a readable rosbag2 database ({err})') from None

    def read(self, ids, coll):
        """Feed the messages of the topic ids to the collector; note any damage."""
        if self.pages is not None:
            pg = self.pages
            try:
                pg.read_messages(self.roots['messages'], ids, coll)
            except (struct.error, ValueError, IndexError, Unsupported) as err:
                self.warnings.append(f'{self.path.name}: malformed SQLite page '
                                     f'({one_line(err)}): the rest is skipped')
            problem = '' if pg.damaged else pg.index_problem() or pg.structure_problem()
            if problem:
                self.warnings.append(f'{self.path.name}: damaged sqlite3 file ({problem}): '
                                     'messages may be missing, misplaced or changed')
            if pg.damaged:
                cut = pg.declared > pg.npages or pg.size % pg.page_size
                where = f'cut after page {pg.npages} of {pg.declared}' if cut else \
                    f'{pg.lost_pages} page(s) of the message table unreadable'
                self.warnings.append(
                    f'{self.path.name}: damaged sqlite3 file ({where}): read the messages of the '
                    'intact pages, the rest is skipped')
            return
        stamps, blobs = [], []
        cur = self.con.execute(
            'SELECT timestamp, data FROM messages WHERE topic_id IN (%s) ORDER BY id'
            % ','.join('?' * len(ids)), ids)
        try:
            for s, b in cur:
                stamps.append(s)
                blobs.append(b)
        except sqlite3.Error as err:
            self.warnings.append(f'{self.path.name}: read stopped after {len(blobs)} messages '
                                 f'({err}); the rest is skipped')
        coll.add_blobs(stamps, blobs)

    def close(self):
        if self.pages is not None:
            self.pages.close()
        if self.con is not None:
            self.con.close()


def _chosen_connections(reader, where, topic):
    """Return the Imu topic of a rosbags reader (:func:`choose_topic`) and its connections."""
    chosen = choose_topic(where, _reader_topics(reader), topic)
    return chosen, [c for c in reader.connections if c.topic == chosen]


def _read_ros1_fast(where, p, topic):
    """Fast path for ROS 1 bags: raw records from rosbags, ROS 1 layout decoded in bulk."""
    reader = any_reader([p], where)
    warnings = []
    try:
        chosen, conns = _chosen_connections(reader, where, topic)
        msgtype = conns[0].msgtype
        coll = Collector(True, lambda b: reader.deserialize(b, msgtype))
        stamps, blobs = [], []
        try:
            for _, stamp, raw in reader.messages(connections=conns):
                stamps.append(stamp)
                blobs.append(raw)
        except Exception as err:
            if not blobs:
                raise InputError(where, f'cannot read messages: {one_line(err)}') from None
            warnings.append(f'read stopped after {len(blobs)} messages: {one_line(err)}')
        coll.add_blobs(stamps, blobs)
        t, data = coll.result()
        warnings += coll.warnings()
    finally:
        reader.close()
    return chosen, t, data, warnings, coll.frame_id
