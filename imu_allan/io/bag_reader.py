"""Read ``sensor_msgs/msg/Imu`` samples from rosbag2 (sqlite3, MCAP) and ROS 1 bags.

Two paths give identical numbers:

* the generic path deserializes every message with ``rosbags`` and converts it with the one
  message -> numpy adapter (:mod:`imu_allan.io.imu_adapter`); about 120-150 k messages/s;
* the fast path decodes the fixed layout of ``sensor_msgs/Imu`` in bulk with numpy. A CDR Imu
  is: 4-byte encapsulation header (``00 01`` = little-endian CDR), ``int32 sec``,
  ``uint32 nanosec``, ``uint32`` frame_id length (with the trailing NUL), the frame_id bytes,
  padding to an 8-byte boundary (counted from the end of the encapsulation header), then 37
  float64 (orientation 4, its covariance 9, angular velocity 3, its covariance 9, linear
  acceleration 3, its covariance 9). ROS 1 has ``uint32 seq, sec, nsec``, the frame_id length
  and bytes (no NUL) and the same 37 float64 with no padding. Messages are grouped by (length,
  frame_id length) so each group is one ``np.frombuffer`` view; anything else (big-endian CDR,
  unexpected length) goes through the generic deserializer.

MCAP files are scanned directly (records, chunks, zstd/lz4 chunk compression) because reading
them record by record through ``AnyReader`` alone caps near 500 k messages/s; runs of equal
message records inside a chunk are sliced out with one numpy view. sqlite3 storage is queried
directly. Damaged input raises :class:`~imu_allan.io.errors.InputError`, or, when part of it is
readable, returns what was read with a line in ``Samples.warnings`` saying what was skipped.

``t`` is the header stamp (``sec + nanosec * 1e-9`` s) in bag order (receive time order).
"""

from binascii import crc32
from collections import defaultdict
import mmap
from pathlib import Path
import sqlite3
import struct

import numpy as np

from ..core.units import AXES
from .errors import InputError
from .imu_adapter import imu_to_row
from .samples import Samples

IMU_TYPE = 'sensor_msgs/msg/Imu'
_IMU_TYPES = {IMU_TYPE, 'sensor_msgs/Imu'}

MCAP_MAGIC = b'\x89MCAP0\r\n'
SQLITE_MAGIC = b'SQLite format 3\x00'
ROS1_MAGIC = b'#ROSBAG V2.0\n'

# Offsets (in float64 units) of the fields used, inside the 37-double tail of an Imu.
_GYRO_OFF = 13
_ACCEL_OFF = 25
_TAIL = 37 * 8


# ----------------------------------------------------------------------------------------------
# Bulk decoding of the fixed Imu layouts


def _cdr_layout(slen):
    """Return (double block start, total length) of a little-endian CDR Imu with frame_id slen."""
    pos = 4 + 4 + 4 + 4 + slen
    pad = (-(pos - 4)) % 8  # CDR aligns relative to the end of the encapsulation header
    return pos + pad, pos + pad + _TAIL


def _ros1_layout(slen):
    """Return (double block start, total length) of a ROS 1 Imu with a frame_id of slen bytes."""
    start = 16 + slen
    return start, start + _TAIL


def _take_f8(rows, start, count):
    """Read ``count`` little-endian float64 starting at byte ``start`` of every row."""
    block = np.ascontiguousarray(rows[:, start:start + 8 * count])
    return block.view('<f8').reshape(rows.shape[0], count)


def _u32(rows, start):
    """Read a little-endian uint32 at byte ``start`` of every row."""
    return np.ascontiguousarray(rows[:, start:start + 4]).view('<u4')[:, 0]


def _decode_rows(rows, ros1):
    """Bulk-decode equal-length serialized Imu messages.

    Parameters
    ----------
    rows : numpy.ndarray
        Shape (k, L) uint8, one serialized message per row.
    ros1 : bool
        ROS 1 serialization instead of CDR.

    Returns
    -------
    ok : numpy.ndarray
        Shape (k,) bool, rows decoded here; the others need the generic deserializer.
    t : numpy.ndarray
        Shape (k,), stamps in seconds (valid where ``ok``).
    data : numpy.ndarray
        Shape (k, 6), rad/s and m/s^2 (valid where ``ok``).

    """
    k, length = rows.shape
    t = np.zeros(k)
    data = np.zeros((k, 6))
    ok = np.zeros(k, dtype=bool)
    if length < 16 + _TAIL:
        return ok, t, data
    slen = _u32(rows, 12)
    if ros1:
        good = np.ones(k, dtype=bool)
        layout = _ros1_layout
    else:
        # Only little-endian plain CDR (encapsulation 00 01) has this byte layout.
        good = (rows[:, 0] == 0) & (rows[:, 1] == 1)
        layout = _cdr_layout
    for s in np.unique(slen[good]):
        start, total = layout(int(s))
        if total != length:
            continue
        sel = good & (slen == s)
        sub = rows[sel] if not sel.all() else rows
        ok[sel] = True
        if ros1:
            sec = _u32(sub, 4).astype(np.float64)
        else:
            sec = _u32(sub, 4).view('<i4').astype(np.float64)
        nsec = _u32(sub, 8).astype(np.float64)
        # Same float operations as the adapter: sec + nanosec * 1e-9.
        t[sel] = sec + nsec * 1e-9
        data[sel, :3] = _take_f8(sub, start + 8 * _GYRO_OFF, 3)
        data[sel, 3:] = _take_f8(sub, start + 8 * _ACCEL_OFF, 3)
    return ok, t, data


class _Collector:
    """Accumulate serialized Imu messages of one connection in file order, decode in bulk."""

    def __init__(self, ros1, deserialize):
        self.ros1 = ros1
        self.deserialize = deserialize
        self.parts = []  # (order, log_time, t, data) arrays
        self.single_order = []
        self.single_time = []
        self.single_blob = []
        self.count = 0

    def add_rows(self, log_time, rows):
        """Add k messages given as a (k, L) uint8 array with their receive times (ns)."""
        k = rows.shape[0]
        order = np.arange(self.count, self.count + k)
        self.count += k
        ok, t, data = _decode_rows(rows, self.ros1)
        if not ok.all():
            for i in np.nonzero(~ok)[0]:
                t[i], data[i] = self._generic(rows[i].tobytes())
        self.parts.append((order, np.asarray(log_time, dtype=np.int64), t, data))

    def add_one(self, log_time, blob):
        """Add one message (bytes) with its receive time (ns)."""
        self.single_order.append(self.count)
        self.single_time.append(log_time)
        self.single_blob.append(blob)
        self.count += 1

    def _generic(self, blob):
        return imu_to_row(self.deserialize(blob))

    def _flush_singles(self):
        if not self.single_blob:
            return
        lens = np.fromiter((len(b) for b in self.single_blob), dtype=np.int64,
                           count=len(self.single_blob))
        order = np.asarray(self.single_order, dtype=np.int64)
        times = np.asarray(self.single_time, dtype=np.int64)
        blobs = self.single_blob
        for length in np.unique(lens):
            idx = np.nonzero(lens == length)[0]
            joined = b''.join([blobs[i] for i in idx])
            rows = np.frombuffer(joined, dtype=np.uint8).reshape(idx.size, int(length))
            ok, t, data = _decode_rows(rows, self.ros1)
            for j in np.nonzero(~ok)[0]:
                t[j], data[j] = self._generic(blobs[idx[j]])
            self.parts.append((order[idx], times[idx], t, data))
        self.single_order, self.single_time, self.single_blob = [], [], []

    def result(self):
        """Return (t, data) sorted by receive time, ties in file order (as rosbags yields)."""
        self._flush_singles()
        if not self.parts:
            return np.zeros(0), np.zeros((0, 6))
        order = np.concatenate([p[0] for p in self.parts])
        log_time = np.concatenate([p[1] for p in self.parts])
        t = np.concatenate([p[2] for p in self.parts])
        data = np.concatenate([p[3] for p in self.parts])
        idx = np.lexsort((order, log_time))
        return t[idx], data[idx]


# ----------------------------------------------------------------------------------------------
# MCAP scanning


def _zstd_decompress(data):
    try:
        from compression import zstd  # Python >= 3.14
    except ImportError:
        from backports import zstd
    return zstd.decompress(data)


def _lz4_decompress(data):
    from lz4.frame import decompress
    return decompress(data)


_DECOMPRESS = {'': bytes, 'zstd': _zstd_decompress, 'lz4': _lz4_decompress}


class _McapScan:
    """Walk the records of an MCAP file, collecting the messages of the wanted Imu channels.

    Works without the summary section, so a truncated file yields what precedes the damage.
    """

    def __init__(self, path, topic=None, collect=True):
        self.path = path
        self.topic = topic
        self.collect = collect
        self.schemas = {}  # id -> name
        self.channels = {}  # id -> (topic, type name, encoding)
        self.counts = defaultdict(int)
        self.collectors = {}
        self.warnings = []
        self.complete = False
        self._deser = None

    def _deserialize(self, blob):
        if self._deser is None:
            from rosbags.typesys import Stores, get_typestore
            ts = get_typestore(Stores.ROS2_JAZZY)
            self._deser = ts.deserialize_cdr
        return self._deser(blob, IMU_TYPE)

    def _wanted(self, cid):
        ch = self.channels.get(cid)
        if ch is None or ch[1] not in _IMU_TYPES:
            return False
        return self.topic is None or ch[0] == self.topic

    def run(self):
        """Scan the whole file."""
        with open(self.path, 'rb') as f:
            size = f.seek(0, 2)
            if size == 0:
                raise InputError(self.path, 'empty file, not a bag')
            f.seek(0)
            if f.read(8) != MCAP_MAGIC:
                raise InputError(self.path, 'not an MCAP file (bad magic bytes)')
            mm = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            buf = memoryview(mm)
            try:
                self._walk(buf, 8, size, top=True)
            finally:
                try:
                    buf.release()
                except BufferError:
                    pass  # a numpy view still refers to it; the GC frees it later
        finally:
            try:
                mm.close()
            except BufferError:
                pass  # a numpy view still refers to it; the GC closes it later

    def _walk(self, buf, pos, end, top):
        u8 = np.frombuffer(buf, dtype=np.uint8, count=end) if self.collect else None
        unpack_q = struct.Struct('<Q').unpack_from
        unpack_h = struct.Struct('<H').unpack_from
        backoff = 0
        where = 'file' if top else 'chunk'
        while pos < end:
            if end - pos < 9:
                self._truncated(pos, end, where)
                return
            op = buf[pos]
            (length,) = unpack_q(buf, pos + 1)
            rec_end = pos + 9 + length
            if rec_end > end:
                if top and op == 0x06:
                    self._partial_chunk(buf, pos, end)
                else:
                    self._truncated(pos, end, where)
                return
            if op == 0x05:
                if length < 22:
                    self.warnings.append(f'bad message record at byte {pos}: rest of {where} '
                                         'skipped')
                    return
                (cid,) = unpack_h(buf, pos + 9)
                self.counts[cid] += 1
                if self.collect and self._wanted(cid):
                    coll = self._collector(cid)
                    stride = 9 + length
                    kmax = (end - pos) // stride
                    if backoff == 0 and kmax > 1:
                        block = u8[pos:pos + kmax * stride].reshape(kmax, stride)
                        # Same opcode, length and channel id as the first record: one run.
                        same = (block[:, 0:11] == block[0, 0:11]).all(axis=1)
                        k = kmax if same.all() else int(np.argmin(same))
                        if k > 1:
                            log_time = np.ascontiguousarray(
                                block[:k, 15:23]).view('<u8')[:, 0].astype(np.int64)
                            coll.add_rows(log_time, block[:k, 31:])
                            self.counts[cid] += k - 1
                            pos += k * stride
                            backoff = 0 if k >= 8 else 32
                            continue
                        backoff = 32
                    elif backoff:
                        backoff -= 1
                    (log_time,) = unpack_q(buf, pos + 15)
                    coll.add_one(log_time, bytes(buf[pos + 31:rec_end]))
            elif op == 0x06 and top:
                self._chunk(buf, pos, rec_end)
            elif op == 0x03:
                (sid,) = unpack_h(buf, pos + 9)
                name, _ = self._string(buf, pos + 11)
                self.schemas[sid] = name
            elif op == 0x04:
                (cid,) = unpack_h(buf, pos + 9)
                (sid,) = unpack_h(buf, pos + 11)
                topic, p = self._string(buf, pos + 13)
                enc, _ = self._string(buf, p)
                self.channels[cid] = (topic, self.schemas.get(sid, ''), enc)
            elif op in (0x0F, 0x02) and top:
                self.complete = True  # DataEnd or Footer: the summary follows
                return
            pos = rec_end
        if top:
            # Records ended cleanly without a DataEnd/Footer: the writer did not finish.
            self.warnings.append('MCAP file has no end marker (recording not closed?); '
                                 'read all complete records')

    @staticmethod
    def _string(buf, pos):
        (n,) = struct.unpack_from('<I', buf, pos)
        return bytes(buf[pos + 4:pos + 4 + n]).decode('utf-8', 'replace'), pos + 4 + n

    def _collector(self, cid):
        if cid not in self.collectors:
            self.collectors[cid] = _Collector(False, self._deserialize)
        return self.collectors[cid]

    def _truncated(self, pos, end, where):
        self.warnings.append(f'{where} truncated at byte {pos} of {end}: rest skipped')

    def _chunk(self, buf, pos, rec_end):
        try:
            _t0, _t1, usize = struct.unpack_from('<QQQ', buf, pos + 9)
            (crc,) = struct.unpack_from('<I', buf, pos + 33)
            comp, p = self._string(buf, pos + 37)
            (csize,) = struct.unpack_from('<Q', buf, p)
            p += 8
            if p + csize > rec_end or comp not in _DECOMPRESS:
                raise ValueError('bad chunk header')
            if comp:
                raw = _DECOMPRESS[comp](buf[p:p + csize])
                if len(raw) != usize:
                    raise ValueError('chunk size mismatch')
                inner = memoryview(raw)
                base = 0
            else:
                if csize != usize:
                    raise ValueError('chunk size mismatch')
                inner = buf
                base = p
            if crc and crc32(inner[base:base + usize]) != crc:
                raise ValueError('chunk checksum mismatch')
        except Exception as err:  # any decoding failure means this chunk is unreadable
            self.warnings.append(f'corrupt chunk at byte {pos} skipped ({err})')
            return
        if base:
            # Walk uncompressed chunks in place (no copy): records are [base, base + usize).
            self._walk_slice(inner, base, base + usize)
        else:
            self._walk(inner, 0, usize, top=False)

    def _partial_chunk(self, buf, pos, end):
        """Read the complete records of an uncompressed chunk cut off by the end of the file."""
        try:
            comp, p = self._string(buf, pos + 37)
            p += 8
        except (struct.error, ValueError):
            comp, p = None, end
        if comp != '' or p >= end:
            self._truncated(pos, end, 'file')
            return
        before = len(self.warnings)
        self._walk_slice(buf, p, end)
        del self.warnings[before:]
        self.warnings.append(f'file truncated at byte {end} inside the chunk starting at byte '
                             f'{pos}: its complete messages were read, the rest is lost')

    def _walk_slice(self, buf, start, stop):
        self._walk(buf[start:stop], 0, stop - start, top=False)


# ----------------------------------------------------------------------------------------------
# Opening and dispatch


def _bag_kind(path):
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
            return _bag_kind(files[0])
        raise InputError(path, 'not a rosbag2 folder (no metadata.yaml)')
    try:
        with open(p, 'rb') as f:
            head = f.read(16)
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    if not head:
        raise InputError(path, 'empty file, not a bag')
    if head.startswith(MCAP_MAGIC):
        return 'mcap', p
    if head.startswith(SQLITE_MAGIC):
        return 'sqlite3', p
    if head.startswith(ROS1_MAGIC):
        return 'ros1', p
    raise InputError(path, 'not a bag (no ROS 1, MCAP or sqlite3 signature)')


def _dir_storage(p):
    """Return (storage id, [files], compressed) of a rosbag2 folder from its metadata.yaml."""
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
    return storage, files, compressed


def _any_reader(paths, where):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    try:
        reader = AnyReader([Path(x) for x in paths],
                           default_typestore=get_typestore(Stores.ROS2_JAZZY))
        reader.open()
    except Exception as err:
        raise InputError(where, f'cannot open bag: {_one_line(err)}') from None
    return reader


def _one_line(err):
    text = ' '.join(str(err).split()) or type(err).__name__
    return text if len(text) < 200 else text[:197] + '...'


def bag_topics(path):
    """Return ``{topic: (type, message count)}`` of a bag (any supported form)."""
    kind, p = _bag_kind(path)
    if kind == 'mcap':
        scan = _McapScan(str(p), collect=False)
        scan.run()
        return {ch[0]: (ch[1], scan.counts.get(cid, 0)) for cid, ch in scan.channels.items()}
    reader = _any_reader([p], path)
    try:
        out = {}
        for c in reader.connections:
            typ, n = out.get(c.topic, (c.msgtype, 0))
            out[c.topic] = (typ, n + c.msgcount)
        return out
    finally:
        reader.close()


def list_imu_topics(path):
    """Return the names of the ``sensor_msgs/Imu`` topics of a bag, in bag order."""
    return [t for t, (typ, _) in bag_topics(path).items() if typ in _IMU_TYPES]


def _choose_topic(path, topics, topic):
    """Pick the Imu topic to read from {topic: (type, count)} or raise InputError."""
    imu = [t for t, (typ, _) in topics.items() if typ in _IMU_TYPES]
    if topic is not None:
        if topic not in topics:
            have = ', '.join(imu) if imu else 'none'
            raise InputError(path, f'no topic {topic} (Imu topics: {have})')
        if topics[topic][0] not in _IMU_TYPES:
            raise InputError(path, f'topic {topic} is {topics[topic][0]}, not {IMU_TYPE}')
        return topic
    if not imu:
        raise InputError(path, f'no {IMU_TYPE} topic in the bag')
    if len(imu) > 1:
        raise InputError(path, f'several Imu topics ({", ".join(imu)}): choose one with --topic')
    return imu[0]


def read_bag(path, topic=None, fast=True):
    """Read the Imu samples of one topic of a bag.

    Parameters
    ----------
    path : str or pathlib.Path
        A rosbag2 folder, a bare ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
    topic : str, optional
        Topic to read; by default the only ``sensor_msgs/Imu`` topic.
    fast : bool
        Use the bulk numpy decoder (False: the generic ``rosbags`` deserializer; same numbers).

    Returns
    -------
    Samples
        ``t`` header stamps in s (bag order), ``data`` (n, 6) rad/s and m/s^2.

    Raises
    ------
    InputError
        Missing path, not a bag, unreadable bag, no/several Imu topics, wrong type, empty topic.

    """
    where = str(path)
    kind, p = _bag_kind(path)
    warnings = []
    if kind == 'dir':
        storage, files, compressed = _dir_storage(p)
        if storage == 'mcap' and not compressed and fast:
            chosen, t, data, warnings = _read_mcap_files(where, files, topic)
        elif storage == 'sqlite3' and not compressed and fast:
            chosen, t, data, warnings = _read_sqlite_files(where, p, files, topic)
        else:
            chosen, t, data, warnings = _read_generic(where, p, topic)
    elif kind == 'mcap' and fast:
        chosen, t, data, warnings = _read_mcap_files(where, [p], topic)
    elif kind == 'sqlite3' and fast:
        chosen, t, data, warnings = _read_sqlite_files(where, None, [p], topic)
    elif kind == 'ros1' and fast:
        chosen, t, data, warnings = _read_ros1_fast(where, p, topic)
    else:
        chosen, t, data, warnings = _read_generic(where, p, topic)
    if t.shape[0] == 0:
        extra = f' ({"; ".join(warnings)})' if warnings else ''
        raise InputError(path, f'topic {chosen} has no messages{extra}')
    return Samples(t=t, data=data, axes=AXES, source=f'{where}:{chosen}', warnings=warnings)


def _read_generic(where, p, topic):
    """Read through ``AnyReader`` and the per-message deserializer (the reference path)."""
    kind = _bag_kind(p)[0]
    if kind == 'mcap':
        # A damaged MCAP cannot be opened by AnyReader: find out with the scanner first.
        scan = _McapScan(str(p), topic, collect=False)
        scan.run()
        if not scan.complete:
            topics = {ch[0]: (ch[1], scan.counts.get(cid, 0))
                      for cid, ch in scan.channels.items()}
            chosen = _choose_mcap_topic(where, [scan], topics, topic)
            return chosen, *_generic_from_scan(p, chosen)
    reader = _any_reader([p], where)
    warnings = []
    try:
        topics = {}
        for c in reader.connections:
            typ, n = topics.get(c.topic, (c.msgtype, 0))
            topics[c.topic] = (typ, n + c.msgcount)
        chosen = _choose_topic(where, topics, topic)
        conns = [c for c in reader.connections if c.topic == chosen]
        stamps, rows = [], []
        try:
            for conn, _, raw in reader.messages(connections=conns):
                s, row = imu_to_row(reader.deserialize(raw, conn.msgtype))
                stamps.append(s)
                rows.append(row)
        except Exception as err:
            if not stamps:
                raise InputError(where, f'cannot read messages: {_one_line(err)}') from None
            warnings.append(f'read stopped after {len(stamps)} messages: {_one_line(err)}')
    finally:
        reader.close()
    t = np.asarray(stamps, dtype=np.float64)
    data = np.asarray(rows, dtype=np.float64).reshape(len(rows), 6)
    return chosen, t, data, warnings


def _choose_mcap_topic(where, scans, topics, topic):
    """Pick the topic of scanned MCAP files; a damaged file with no Imu data is an error."""
    warnings = [w for scan in scans for w in scan.warnings]
    if warnings and not any(typ in _IMU_TYPES for typ, _ in topics.values()):
        raise InputError(where, f'damaged MCAP, no Imu data readable ({warnings[0]})')
    return _choose_topic(where, topics, topic)


def _generic_from_scan(p, chosen):
    """Generic decoding (one message at a time) of the readable part of a damaged MCAP file."""
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    scan = _McapRaw(str(p), chosen)
    rows = [imu_to_row(ts.deserialize_cdr(b, IMU_TYPE)) for b in scan.blobs()]
    t = np.array([r[0] for r in rows], dtype=np.float64)
    data = np.array([r[1] for r in rows], dtype=np.float64).reshape(len(rows), 6)
    return t, data, scan.warnings


class _McapRaw(_McapScan):
    """Scanner variant that keeps every raw message blob (in receive-time order)."""

    def _collector(self, cid):
        if cid not in self.collectors:
            self.collectors[cid] = _RawCollector()
        return self.collectors[cid]

    def blobs(self):
        self.run()
        out = []
        for coll in self.collectors.values():
            out.extend(coll.sorted())
        return out


class _RawCollector:
    def __init__(self):
        self.items = []

    def add_rows(self, log_time, rows):
        for lt, row in zip(log_time, rows):
            self.items.append((int(lt), len(self.items), row.tobytes()))

    def add_one(self, log_time, blob):
        self.items.append((int(log_time), len(self.items), blob))

    def sorted(self):
        return [b for _, _, b in sorted(self.items)]


def _read_mcap_files(where, files, topic):
    """Fast path for MCAP storage: scan every file, bulk-decode the chosen topic."""
    scans = []
    for f in files:
        scan = _McapScan(str(f), topic)
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
    ts, ds, warnings = [], [], []
    for scan in scans:
        for cid, coll in scan.collectors.items():
            if scan.channels[cid][0] == chosen:
                t, d = coll.result()
                ts.append(t)
                ds.append(d)
        warnings += scan.warnings
    if not ts:
        return chosen, np.zeros(0), np.zeros((0, 6)), warnings
    t = np.concatenate(ts)
    data = np.concatenate(ds)
    return chosen, t, data, warnings


def _read_sqlite_files(where, folder, files, topic):
    """Fast path for sqlite3 storage: one query per file, bulk-decode the blobs."""
    from rosbags.typesys import Stores, get_typestore
    deser = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr
    topics = {}
    per_file = []
    for f in files:
        try:
            con = sqlite3.connect(f'file:{f}?mode=ro&immutable=1', uri=True)
        except sqlite3.Error as err:
            raise InputError(where, f'cannot open sqlite3 storage: {err}') from None
        try:
            rows = con.execute('SELECT id, name, type FROM topics').fetchall()
        except sqlite3.Error as err:
            con.close()
            raise InputError(where, f'not a readable rosbag2 database ({err})') from None
        per_file.append((con, rows))
        for _tid, name, typ in rows:
            typ0, n = topics.get(name, (typ, 0))
            topics[name] = (typ0, n)
    try:
        chosen = _choose_topic(where, topics, topic)
        ts, ds, warnings = [], [], []
        for (con, rows), f in zip(per_file, files):
            ids = [tid for tid, name, _ in rows if name == chosen]
            if not ids:
                continue
            coll = _Collector(False, lambda b: deser(b, IMU_TYPE))
            stamps, blobs = [], []
            cur = con.execute(
                'SELECT timestamp, data FROM messages WHERE topic_id IN (%s) ORDER BY id'
                % ','.join('?' * len(ids)), ids)
            try:
                while True:
                    batch = cur.fetchmany(65536)
                    if not batch:
                        break
                    for s, b in batch:
                        stamps.append(s)
                        blobs.append(b)
            except sqlite3.Error as err:
                warnings.append(f'{Path(f).name}: read stopped after {len(blobs)} messages '
                                f'({err}); the rest is skipped')
            _add_blobs(coll, stamps, blobs)
            t, d = coll.result()
            ts.append(t)
            ds.append(d)
    finally:
        for con, _ in per_file:
            con.close()
    if not ts:
        return chosen, np.zeros(0), np.zeros((0, 6)), warnings
    return chosen, np.concatenate(ts), np.concatenate(ds), warnings


def _add_blobs(coll, stamps, blobs):
    """Feed blobs to a collector grouped by length, keeping their order numbers."""
    n = len(blobs)
    if n == 0:
        return
    lens = np.fromiter(map(len, blobs), dtype=np.int64, count=n)
    times = np.asarray(stamps, dtype=np.int64)
    base = coll.count
    for length in np.unique(lens):
        idx = np.nonzero(lens == length)[0]
        if idx.size == n:
            joined = b''.join(blobs)
        else:
            joined = b''.join([blobs[i] for i in idx])
        rows = np.frombuffer(joined, dtype=np.uint8).reshape(idx.size, int(length))
        ok, t, data = _decode_rows(rows, coll.ros1)
        for j in np.nonzero(~ok)[0]:
            t[j], data[j] = coll._generic(blobs[idx[j]])
        coll.parts.append((base + idx, times[idx], t, data))
    coll.count = base + n


def _read_ros1_fast(where, p, topic):
    """Fast path for ROS 1 bags: raw records from rosbags, ROS 1 layout decoded in bulk."""
    reader = _any_reader([p], where)
    warnings = []
    try:
        topics = {}
        for c in reader.connections:
            typ, n = topics.get(c.topic, (c.msgtype, 0))
            topics[c.topic] = (typ, n + c.msgcount)
        chosen = _choose_topic(where, topics, topic)
        conns = [c for c in reader.connections if c.topic == chosen]
        msgtype = conns[0].msgtype
        coll = _Collector(True, lambda b: reader.deserialize(b, msgtype))
        stamps, blobs = [], []
        try:
            for _, stamp, raw in reader.messages(connections=conns):
                stamps.append(stamp)
                blobs.append(raw)
        except Exception as err:
            if not blobs:
                raise InputError(where, f'cannot read messages: {_one_line(err)}') from None
            warnings.append(f'read stopped after {len(blobs)} messages: {_one_line(err)}')
        _add_blobs(coll, stamps, blobs)
        t, data = coll.result()
    finally:
        reader.close()
    return chosen, t, data, warnings
