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

The fast path reads the storage itself, because handing over one raw message at a time
(``AnyReader``: about 500 k/s for MCAP; the ``sqlite3`` module: about 700 k rows/s) would cap
it below 1 M messages/s:

* MCAP: records and chunks are walked directly (zstd/lz4 chunk compression, CRC checked);
  runs of equal message records inside a chunk are sliced out with one numpy view;
* sqlite3: the ``messages`` table's B-tree is walked in the file (SQLite file format) and its
  leaf cells decoded in numpy batches; SQL queries remain the fallback (write-ahead log, odd
  layouts);
* ROS 1: chunks (none/bz2/lz4) are walked directly, runs of equal records sliced as for MCAP.

Damaged input raises :class:`~imu_allan.io.errors.InputError`, or, when part of it is
readable, returns what was read with a line in ``Samples.warnings`` saying what was skipped:
a truncated MCAP or ROS 1 file gives its complete chunks (and the complete records of an
uncompressed chunk cut short), a corrupt compressed chunk is skipped, a truncated sqlite3 file
gives the rows of its intact pages. rosbags refuses such files; the generic path then uses the
same direct readers with per-message deserialization.

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


def _decode_at(u8, off, length, ros1):
    """Bulk-decode serialized Imu messages of one length found at byte offsets of a buffer.

    Same result as :func:`_decode_rows` on the gathered rows, but only the header and the 48
    bytes of angular velocity and linear acceleration are gathered. (Byte gathers beat word
    gathers through unaligned views here; callers pass batches of about 10^4 messages so the
    index arrays stay small.)
    """
    k = off.shape[0]
    t = np.zeros(k)
    data = np.zeros((k, 6))
    ok = np.zeros(k, dtype=bool)
    if length < 16 + _TAIL or k == 0:
        return ok, t, data
    head = u8[off[:, None] + np.arange(16)]
    slen = _u32(head, 12)
    if ros1:
        good = np.ones(k, dtype=bool)
        layout = _ros1_layout
    else:
        good = (head[:, 0] == 0) & (head[:, 1] == 1)
        layout = _cdr_layout
    span = np.arange(24)
    for s in np.unique(slen[good]):
        start, total = layout(int(s))
        if total != length:
            continue
        sel = good & (slen == s)
        ok[sel] = True
        h = head[sel]
        sec = _u32(h, 4).astype(np.float64) if ros1 else \
            _u32(h, 4).view('<i4').astype(np.float64)
        t[sel] = sec + _u32(h, 8).astype(np.float64) * 1e-9
        # One gather for both vectors: gyro bytes then accel bytes, 48 per message.
        cols = np.concatenate([start + 8 * _GYRO_OFF + span, start + 8 * _ACCEL_OFF + span])
        data[sel] = u8[off[sel][:, None] + cols].view('<f8')
    return ok, t, data


class _Collector:
    """Accumulate serialized Imu messages of one connection in file order, decode in bulk."""

    def __init__(self, ros1, deserialize, force_generic=False):
        self.ros1 = ros1
        self.deserialize = deserialize
        self.force_generic = force_generic  # reference path: every message deserialized
        self.parts = []  # (order, log_time, t, data) arrays
        self.single_order = []
        self.single_time = []
        self.single_blob = []
        self.count = 0
        self.undecodable = 0  # messages the deserializer rejected (dropped, with a warning)

    def add_rows(self, log_time, rows):
        """Add k messages given as a (k, L) uint8 array with their receive times (ns)."""
        k = rows.shape[0]
        order = np.arange(self.count, self.count + k)
        self.count += k
        ok, t, data = _decode_rows(rows, self.ros1)
        if self.force_generic:
            ok[:] = False
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
        """Deserialize one message; NaN stamp (dropped in :meth:`result`) if it is garbage."""
        try:
            return imu_to_row(self.deserialize(blob))
        except Exception:  # any deserializer failure means this one message is unusable
            self.undecodable += 1
            return np.nan, np.full(6, np.nan)

    def warnings(self):
        """Warning lines about this collector's messages."""
        if self.undecodable:
            return [f'{self.undecodable} message(s) could not be decoded and were skipped']
        return []

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
            if self.force_generic:
                ok[:] = False
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
        if order.shape[0] > 1 and np.all(np.diff(order) > 0) and np.all(np.diff(log_time) >= 0):
            return self._drop_undecodable(t, data)  # already in order (usual): no sort needed
        idx = np.lexsort((order, log_time))
        t, data = t[idx], data[idx]
        return self._drop_undecodable(t, data)

    def _drop_undecodable(self, t, data):
        if not self.undecodable:
            return t, data
        keep = ~np.isnan(t)
        return t[keep], data[keep]


def _map_file(f):
    """Memory-map a whole file read-only."""
    return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)


def _jazzy_deserialize(blob):
    """Deserialize one CDR Imu with the Jazzy typestore (built once, on first use)."""
    global _JAZZY_STORE
    if _JAZZY_STORE is None:
        from rosbags.typesys import get_typestore, Stores
        _JAZZY_STORE = get_typestore(Stores.ROS2_JAZZY)
    return _JAZZY_STORE.deserialize_cdr(blob, IMU_TYPE)


_JAZZY_STORE = None


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
_MCAP_OPS = frozenset(range(0x01, 0x11))  # record opcodes of MCAP v0 (0x80-0xFF: private)


class _McapScan:
    """Walk the records of an MCAP file, collecting the messages of the wanted Imu channels.

    Works without the summary section, so a truncated file yields what precedes the damage.
    """

    def __init__(self, path, topic=None, collect=True, force_generic=False):
        self.path = path
        self.topic = topic
        self.collect = collect
        self.force_generic = force_generic
        self.schemas = {}  # id -> name
        self.channels = {}  # id -> (topic, type name, encoding)
        self.counts = defaultdict(int)
        self.collectors = {}
        self.warnings = []
        self.complete = False
        self.chunk_offsets = []

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
            mm = _map_file(f)
        try:
            buf = memoryview(mm)
            try:
                self._read_summary(buf, size)
                self._walk(buf, 8, size, top=True)
            except (struct.error, ValueError, IndexError, KeyError) as err:
                self.warnings.append(f'malformed MCAP record ({_one_line(err)}): '
                                     'rest of the file skipped')
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

    def _read_summary(self, buf, size):
        """Pre-read schemas, channels and chunk offsets from the summary, if the footer is intact.

        With them a damaged first chunk (which holds the channel definitions) or a damaged
        record header does not cost the rest of the file: the walk resumes at the next chunk.
        """
        self.chunk_offsets = []
        if size < 8 + 37 + 37:
            return
        foot = size - 37
        try:
            if buf[foot] != 0x02 or bytes(buf[size - 8:size]) != MCAP_MAGIC:
                return
            (start,) = struct.unpack_from('<Q', buf, foot + 9)
            pos = start
            while 8 < start <= pos < foot:
                op = buf[pos]
                (length,) = struct.unpack_from('<Q', buf, pos + 1)
                if op == 0x03:
                    (sid,) = struct.unpack_from('<H', buf, pos + 9)
                    self.schemas.setdefault(sid, self._string(buf, pos + 11)[0])
                elif op == 0x04:
                    cid, sid = struct.unpack_from('<HH', buf, pos + 9)
                    topic, p = self._string(buf, pos + 13)
                    self.channels.setdefault(
                        cid, (topic, self.schemas.get(sid, ''), self._string(buf, p)[0]))
                elif op == 0x08:
                    self.chunk_offsets.append(struct.unpack_from('<Q', buf, pos + 9 + 16)[0])
                pos += 9 + length
        except (struct.error, IndexError, ValueError):
            pass  # a damaged summary only means no help for the walk
        self.chunk_offsets.sort()

    def _resync(self, pos, end, problem):
        """Position of the next indexed chunk after a damaged record, or None (with a warning)."""
        nxt = next((o for o in getattr(self, 'chunk_offsets', ()) if pos < o < end), None)
        if nxt is None:
            self.warnings.append(f'file {problem} at byte {pos} of {end}: rest skipped')
        else:
            self.warnings.append(f'damaged record at byte {pos} ({problem}): skipped to the '
                                 f'next chunk at byte {nxt}')
        return nxt

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
            if rec_end > end or (top and op not in _MCAP_OPS):
                if top and op == 0x06 and not any(pos < o < end for o in self.chunk_offsets):
                    self._partial_chunk(buf, pos, end)
                    return
                if not top:
                    self._truncated(pos, end, where)
                    return
                pos = self._resync(pos, end, 'truncated' if rec_end > end else 'damaged')
                if pos is None:
                    return
                continue
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
        # Keyed by topic: several channels of one topic merge in receive-time order.
        topic = self.channels[cid][0]
        if topic not in self.collectors:
            self.collectors[topic] = _Collector(False, _jazzy_deserialize, self.force_generic)
        return self.collectors[topic]

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
        try:
            if base:
                # Walk uncompressed chunks in place (no copy): records are [base, base + usize).
                self._walk_slice(inner, base, base + usize)
            else:
                self._walk(inner, 0, usize, top=False)
        except (struct.error, ValueError, IndexError, KeyError) as err:
            self.warnings.append(f'malformed record in the chunk at byte {pos} '
                                 f'({_one_line(err)}): rest of that chunk skipped')

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
    from rosbags.typesys import get_typestore, Stores
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
    """Return ``{topic: (type, message count)}`` of a bag (any supported form).

    Uses the bag's index through rosbags; a damaged MCAP or ROS 1 file is scanned instead
    (counting the readable messages).
    """
    kind, p = _bag_kind(path)
    try:
        reader = _any_reader([p], path)
    except InputError:
        scan = None
        if kind == 'mcap' or (kind == 'dir' and _dir_storage(p)[0] == 'mcap'):
            scan = _McapScan(str(_mcap_files(p, kind)[0]), collect=False)
            names = scan.channels
        elif kind == 'ros1':
            scan = _Ros1Scan(p, collect=False)
            names = scan.conns
        if scan is None:
            raise
        scan.run()
        return {ch[0]: (ch[1], scan.counts.get(cid, 0)) for cid, ch in names.items()}
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
            chosen, t, data, warnings = _read_sqlite_files(where, files, topic)
        else:
            chosen, t, data, warnings = _read_generic(where, p, topic)
    elif kind == 'mcap' and fast:
        chosen, t, data, warnings = _read_mcap_files(where, [p], topic)
    elif kind == 'sqlite3' and fast:
        chosen, t, data, warnings = _read_sqlite_files(where, [p], topic)
    elif kind == 'ros1' and fast:
        res = _read_ros1_scan(where, p, topic)
        if res is None:
            res = _read_ros1_fast(where, p, topic)
        chosen, t, data, warnings = res
    else:
        chosen, t, data, warnings = _read_generic(where, p, topic)
    if t.shape[0] == 0:
        extra = f' ({"; ".join(warnings)})' if warnings else ''
        raise InputError(path, f'topic {chosen} has no messages{extra}')
    return Samples(t=t, data=data, axes=AXES, source=f'{where}:{chosen}', warnings=warnings)


def _read_generic(where, p, topic):
    """Read through ``AnyReader`` and the per-message deserializer (the reference path)."""
    kind = _bag_kind(p)[0]
    try:
        reader = _any_reader([p], where)
    except InputError:
        # rosbags cannot open damaged files (no MCAP footer, no ROS 1 index, malformed SQLite):
        # read what is left with the direct readers, deserializing message by message.
        if _mcap_files(p, kind):
            return _read_mcap_files(where, _mcap_files(p, kind), topic, force_generic=True)
        if kind == 'ros1':
            # rosbags needs the index at the end: read the chunks of a cut bag one by one.
            res = _read_ros1_scan(where, p, topic, force_generic=True)
            if res is None:
                raise
            return res
        files = _sqlite_files(p, kind)
        if not files:
            raise
        return _read_sqlite_files(where, files, topic, force_generic=True)
    warnings = []
    try:
        topics = {}
        for c in reader.connections:
            typ, n = topics.get(c.topic, (c.msgtype, 0))
            topics[c.topic] = (typ, n + c.msgcount)
        chosen = _choose_topic(where, topics, topic)
        conns = [c for c in reader.connections if c.topic == chosen]
        stamps, rows = [], []
        bad = 0
        try:
            for conn, _, raw in reader.messages(connections=conns):
                try:
                    s, row = imu_to_row(reader.deserialize(raw, conn.msgtype))
                except Exception:  # one garbled message: skip it, as the fast path does
                    bad += 1
                    continue
                stamps.append(s)
                rows.append(row)
        except Exception as err:
            if _mcap_files(p, kind):
                # A corrupt chunk stops rosbags; the scanner skips just that chunk.
                reader.close()
                reader = None
                return _read_mcap_files(where, _mcap_files(p, kind), topic, force_generic=True)
            if not stamps:
                raise InputError(where, f'cannot read messages: {_one_line(err)}') from None
            warnings.append(f'read stopped after {len(stamps)} messages: {_one_line(err)}')
        if bad:
            warnings.append(f'{bad} message(s) could not be decoded and were skipped')
    finally:
        if reader is not None:
            reader.close()
    t = np.asarray(stamps, dtype=np.float64)
    data = np.asarray(rows, dtype=np.float64).reshape(len(rows), 6)
    return chosen, t, data, warnings


def _mcap_files(p, kind):
    """The MCAP storage files of a bag, or [] if it is not an uncompressed MCAP bag."""
    if kind == 'mcap':
        return [p]
    if kind == 'dir':
        storage, files, compressed = _dir_storage(p)
        if storage == 'mcap' and not compressed:
            return files
    return []


def _sqlite_files(p, kind):
    """The sqlite3 storage files of a bag, or [] if it is not sqlite3."""
    if kind == 'sqlite3':
        return [p]
    if kind == 'dir':
        storage, files, compressed = _dir_storage(p)
        if storage == 'sqlite3' and not compressed:
            return files
    return []


def _choose_mcap_topic(where, scans, topics, topic):
    """Pick the topic of scanned MCAP files; a damaged file with no Imu data is an error."""
    warnings = [w for scan in scans for w in scan.warnings]
    if warnings and not any(typ in _IMU_TYPES for typ, _ in topics.values()):
        raise InputError(where, f'damaged MCAP, no Imu data readable ({warnings[0]})')
    return _choose_topic(where, topics, topic)


def _join(ts, ds):
    """Concatenate per-file results (no copy for the usual single file)."""
    if len(ts) == 1:
        return ts[0], ds[0]
    return np.concatenate(ts), np.concatenate(ds)


def _read_mcap_files(where, files, topic, force_generic=False):
    """Fast path for MCAP storage: scan every file, bulk-decode the chosen topic."""
    scans = []
    for f in files:
        scan = _McapScan(str(f), topic, force_generic=force_generic)
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
    encodings = {ch[2] for scan in scans for ch in scan.channels.values() if ch[0] == chosen}
    if encodings - {'cdr'}:
        raise InputError(where, f'topic {chosen} uses message encoding '
                                f'{", ".join(sorted(encodings - {"cdr"}))}; only CDR is supported')
    ts, ds, warnings = [], [], []
    for scan in scans:
        if chosen in scan.collectors:
            t, d = scan.collectors[chosen].result()
            ts.append(t)
            ds.append(d)
            warnings += scan.collectors[chosen].warnings()
        warnings += scan.warnings
    if not ts:
        return chosen, np.zeros(0), np.zeros((0, 6)), warnings
    return chosen, *_join(ts, ds), warnings


def _read_sqlite_files(where, files, topic, force_generic=False):
    """Fast path for sqlite3 storage: walk the messages B-tree of each file, decode in bulk.

    Falls back to SQL queries for files the page reader does not handle (write-ahead log
    present, unusual record layout).
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
        chosen = _choose_topic(where, topics, topic)
        ts, ds, warnings = [], [], []
        for src in opened:
            ids = [tid for tid, name, _ in src.topic_rows if name == chosen]
            coll = _Collector(False, _jazzy_deserialize, force_generic)
            if ids:
                src.read(ids, coll)
            t, d = coll.result()
            warnings += src.warnings + coll.warnings()
            ts.append(t)
            ds.append(d)
    finally:
        for src in opened:
            src.close()
    return chosen, *_join(ts, ds), warnings


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
                self.pages = _SqlitePages(path)
                roots = self.pages.schema()
                if 'messages' not in roots or 'topics' not in roots:
                    raise _Unsupported('no rosbag2 tables')
                self.roots = roots
                self.topic_rows = self.pages.topics(roots['topics'])
                return
            except (_Unsupported, IndexError, struct.error, ValueError, TypeError):
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
            except (struct.error, ValueError, IndexError, _Unsupported) as err:
                self.warnings.append(f'{self.path.name}: malformed SQLite page '
                                     f'({_one_line(err)}): the rest is skipped')
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
            while True:
                batch = cur.fetchmany(65536)
                if not batch:
                    break
                for s, b in batch:
                    stamps.append(s)
                    blobs.append(b)
        except sqlite3.Error as err:
            self.warnings.append(f'{self.path.name}: read stopped after {len(blobs)} messages '
                                 f'({err}); the rest is skipped')
        _add_blobs(coll, stamps, blobs)

    def close(self):
        if self.pages is not None:
            self.pages.close()
        if self.con is not None:
            self.con.close()


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
        if coll.force_generic:
            ok[:] = False
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
        warnings += coll.warnings()
    finally:
        reader.close()
    return chosen, t, data, warnings


# ----------------------------------------------------------------------------------------------
# Direct reading of rosbag2 sqlite3 files (SQLite file format, https://sqlite.org/fileformat.html)
#
# The ``sqlite3`` module hands over one Python tuple per row, which caps near 700 k rows/s here;
# a rosbag2 ``messages`` table is a plain rowid B-tree whose leaf cells are (NULL id alias,
# topic_id, timestamp, data), so walking the tree and decoding the cells with numpy is faster,
# and it also reads what is left of a truncated file (SQLite itself refuses such a file).

_SERIAL_SIZE = np.array([0, 1, 2, 3, 4, 6, 8, 8, 0, 0, -1, -1], dtype=np.int64)
_PAGE_BATCH = 512  # leaf pages decoded per numpy batch (bounds the index arrays' memory)


class _Unsupported(Exception):
    """The file uses a feature the direct readers do not handle: use the other path."""


def _varints(u8, pos):
    """Decode SQLite varints (big-endian, 7 bits per byte, 9 bytes max) at positions ``pos``."""
    n = pos.shape[0]
    val = np.zeros(n, dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)
    done = np.zeros(n, dtype=bool)
    last = u8.shape[0] - 1
    for k in range(9):
        b = u8[np.minimum(pos + k, last)].astype(np.int64)
        live = ~done
        if k < 8:
            val = np.where(live, (val << 7) | (b & 0x7F), val)
            size = np.where(live, k + 1, size)
            done = done | (b < 0x80)
        else:
            val = np.where(live, (val << 8) | b, val)
            size = np.where(live, 9, size)
            done[:] = True
        if done.all():
            break
    return val, size


def _be_ints(u8, pos, serial):
    """Decode big-endian signed integers of SQLite serial types 1-6, 8 (0) and 9 (1)."""
    out = np.zeros(pos.shape[0], dtype=np.int64)
    out[serial == 9] = 1
    for st in (1, 2, 3, 4, 5, 6):
        sel = serial == st
        if not sel.any():
            continue
        size = int(_SERIAL_SIZE[st])
        idx = pos[sel][:, None] + np.arange(size)
        b = u8[idx].astype(np.int64)
        v = np.zeros(idx.shape[0], dtype=np.int64)
        for j in range(size):
            v = (v << 8) | b[:, j]
        if size < 8:
            sign = np.int64(1) << (8 * size - 1)
            v = np.where(v >= sign, v - (sign << 1), v)
        out[sel] = v
    return out


def _record_headers(u8, rec):
    """Parse 4-column record headers at ``rec``: (size, 4 serial types, consistent flag).

    The cells of one table mostly share one header (same column types, same blob length), so
    the first header is parsed and compared byte-wise with the others; only the differing ones
    are parsed varint by varint.
    """
    def parse(pos):
        hs, n3 = _varints(u8, pos)
        s0, a = _varints(u8, pos + n3)
        s1, b = _varints(u8, pos + n3 + a)
        s2, c = _varints(u8, pos + n3 + a + b)
        s3, d = _varints(u8, pos + n3 + a + b + c)
        return hs, s0, s1, s2, s3, hs == n3 + a + b + c + d
    first = parse(rec[:1])
    hs0 = int(first[0][0])
    n = rec.shape[0]
    if not first[5][0] or not 0 < hs0 <= 16:
        return parse(rec)
    span = np.arange(hs0)
    same = (u8[rec[:, None] + span] == u8[rec[0] + span]).all(axis=1)
    out = [np.full(n, int(x[0]), dtype=np.int64) for x in first[:5]] + [np.ones(n, dtype=bool)]
    if not same.all():
        idx = np.nonzero(~same)[0]
        for dst, src in zip(out, parse(rec[idx])):
            dst[idx] = src
    return tuple(out)


class _SqlitePages:
    """Minimal reader of a SQLite database file for rosbag2's tables."""

    def __init__(self, path):
        self.path = str(path)
        with open(self.path, 'rb') as f:
            self.size = f.seek(0, 2)
            f.seek(0)
            head = f.read(100)
            if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
                raise InputError(self.path, 'not an SQLite database')
            self.mm = _map_file(f)
        self.u8 = np.frombuffer(self.mm, dtype=np.uint8)
        ps = struct.unpack_from('>H', head, 16)[0]
        self.page_size = 65536 if ps == 1 else ps
        if self.page_size < 512 or self.page_size & (self.page_size - 1):
            raise InputError(self.path, 'damaged SQLite header (bad page size)')
        self.usable = self.page_size - head[20]
        self.npages = self.size // self.page_size
        declared = struct.unpack_from('>I', head, 28)[0]
        valid = struct.unpack_from('>I', head, 24)[0] == struct.unpack_from('>I', head, 92)[0]
        self.declared = declared if valid and declared else self.npages
        self.lost_pages = 0  # referenced pages beyond the end of the file or not B-tree pages

    def close(self):
        self.u8 = None
        try:
            self.mm.close()
        except BufferError:
            pass  # a view still refers to the map; the GC frees it

    def _page(self, no):
        """Byte offset of page ``no`` and of its B-tree header, or None if it is missing."""
        if no < 1 or no > self.npages:
            return None
        base = (no - 1) * self.page_size
        return base, base + (100 if no == 1 else 0)

    def _ptrs(self, hdr, ncell, extra):
        start = hdr + 8 + extra
        raw = self.u8[start:start + 2 * ncell].astype(np.int64)
        return raw[0::2] * 256 + raw[1::2]

    def leaf_pages(self, root):
        """Return the leaf page numbers of a table B-tree in key order (missing ones counted).

        Expands interior pages in place until only leaves remain (SQLite B-trees are balanced,
        so this takes one pass per tree level); page types are checked with numpy.
        """
        u8 = self.u8
        pages = np.array([root], dtype=np.int64)
        while True:
            present = (pages >= 1) & (pages <= self.npages)
            if not present.all():
                self.lost_pages += int((~present).sum())
                pages = pages[present]
            hdr = (pages - 1) * self.page_size + np.where(pages == 1, 100, 0)
            kind = u8[hdr] if pages.size else np.zeros(0, dtype=np.uint8)
            known = (kind == 0x0D) | (kind == 0x05)
            if not known.all():
                self.lost_pages += int((~known).sum())
                pages, hdr, kind = pages[known], hdr[known], kind[known]
            interior = np.nonzero(kind == 0x05)[0]
            if interior.size == 0:
                return pages.tolist()
            parts, last = [], 0
            for i in interior.tolist():
                parts.append(pages[last:i])
                parts.append(self._children(int(pages[i]), int(hdr[i])))
                last = i + 1
            parts.append(pages[last:])
            pages = np.concatenate(parts)

    def _children(self, no, hdr):
        """Child page numbers of an interior table page, in key order."""
        u8 = self.u8
        base = (no - 1) * self.page_size
        ncell = int(u8[hdr + 3]) * 256 + int(u8[hdr + 4])
        right = struct.unpack_from('>I', self.mm, hdr + 8)[0]
        ptrs = self._ptrs(hdr, ncell, 4)
        if ptrs.size and (ptrs.max() + 4 > self.page_size or 12 + 2 * ncell > self.page_size):
            self.lost_pages += 1
            return np.zeros(0, dtype=np.int64)
        b = u8[(base + ptrs)[:, None] + np.arange(4)].astype(np.int64)
        children = (b[:, 0] << 24) | (b[:, 1] << 16) | (b[:, 2] << 8) | b[:, 3]
        return np.append(children, right)

    def _payload(self, cell_off, page_base):
        """Full payload of one table-leaf cell (following overflow pages) and its rowid."""
        u8 = self.u8
        pos = np.array([cell_off])
        p, n1 = _varints(u8, pos)
        rowid, n2 = _varints(u8, pos + n1)
        p, start = int(p[0]), cell_off + int(n1[0]) + int(n2[0])
        usable = self.usable
        x = usable - 35
        if p <= x:
            return int(rowid[0]), bytes(self.mm[start:start + p])
        m = ((usable - 12) * 32 // 255) - 23
        k = m + ((p - m) % (usable - 4))
        local = k if k <= x else m
        out = bytearray(self.mm[start:start + local])
        nxt = struct.unpack_from('>I', self.mm, start + local)[0]
        while len(out) < p and nxt:
            loc = self._page(nxt)
            if loc is None:
                raise _Unsupported('overflow page missing')
            base = loc[0]
            nxt = struct.unpack_from('>I', self.mm, base)[0]
            take = min(p - len(out), usable - 4)
            out += self.mm[base + 4:base + 4 + take]
        return int(rowid[0]), bytes(out)

    @staticmethod
    def _record(payload):
        """Decode a record (list of Python values) from its payload bytes."""
        def varint(buf, i):
            v = 0
            for k in range(9):
                b = buf[i + k]
                if k == 8:
                    return (v << 8) | b, i + 9
                v = (v << 7) | (b & 0x7F)
                if b < 0x80:
                    return v, i + k + 1
            return v, i + 9  # pragma: no cover
        hs, i = varint(payload, 0)
        types = []
        while i < hs:
            st, i = varint(payload, i)
            types.append(st)
        vals, j = [], hs
        for st in types:
            if st in (0, 8, 9):
                vals.append(None if st == 0 else st - 8)
            elif st <= 6:
                size = int(_SERIAL_SIZE[st])
                vals.append(int.from_bytes(payload[j:j + size], 'big', signed=True))
                j += size
            elif st == 7:
                vals.append(struct.unpack_from('>d', payload, j)[0])
                j += 8
            elif st >= 12:
                size = (st - 12) // 2
                raw = payload[j:j + size]
                vals.append(raw if st % 2 == 0 else raw.decode('utf-8', 'replace'))
                j += size
            else:
                raise _Unsupported(f'serial type {st}')
        return vals

    def table_rows(self, root):
        """All rows of a small table as (rowid, values) (Python, not for ``messages``)."""
        rows = []
        for no in self.leaf_pages(root):
            base, hdr = self._page(no)
            ncell = int(self.u8[hdr + 3]) * 256 + int(self.u8[hdr + 4])
            for ptr in self._ptrs(hdr, ncell, 0).tolist():
                rowid, payload = self._payload(base + ptr, base)
                rows.append((rowid, self._record(payload)))
        return rows

    def schema(self):
        """Return {table name: root page} from sqlite_schema."""
        out = {}
        for _, vals in self.table_rows(1):
            if len(vals) >= 4 and vals[0] == 'table':
                out[vals[1]] = vals[3]
        return out

    def topics(self, root):
        """Return [(topic id, name, type)] from rosbag2's topics table."""
        out = []
        for rowid, vals in self.table_rows(root):
            tid = rowid if vals[0] is None else vals[0]
            out.append((tid, vals[1], vals[2]))
        return out

    @property
    def damaged(self):
        """True if the file is shorter than its header says or the tree lost pages."""
        return bool(self.declared > self.npages or self.size % self.page_size or self.lost_pages)

    def read_messages(self, root, topic_ids, coll):
        """Feed the messages of ``topic_ids`` to a collector, in numpy batches.

        An intact file is read along the B-tree; a damaged one by trying every table-leaf
        page (a cut file can lose the interior pages that lead to intact leaves). Only cells
        shaped like rosbag2 message rows are taken; the rowid orders them.
        """
        leaves = np.asarray(self.leaf_pages(root), dtype=np.int64)
        if self.damaged:
            every = np.arange(1, self.npages + 1, dtype=np.int64)
            hdr = (every - 1) * self.page_size + np.where(every == 1, 100, 0)
            leaves = every[self.u8[hdr] == 0x0D]
        wanted = np.asarray(sorted(topic_ids), dtype=np.int64)
        for b0 in range(0, leaves.shape[0], _PAGE_BATCH):
            self._batch(leaves[b0:b0 + _PAGE_BATCH], wanted, coll)

    def _batch(self, pages, wanted, coll):
        ps = self.page_size
        base = (pages - 1) * ps
        # Copy the batch's byte range once (a sequential read the CPU prefetches), then gather
        # from that cache-warm copy instead of scattering reads over the whole mapped file.
        lo, hi = int(base.min()), int(base.max()) + ps
        if hi - lo <= 4 * pages.shape[0] * ps:
            u8 = self.u8[lo:hi].copy()
            shift = lo
            base = base - lo
        else:
            u8, shift = self.u8, 0
        hdr = base + np.where(pages == 1, 100, 0)
        ncell = u8[hdr + 3].astype(np.int64) * 256 + u8[hdr + 4]
        good_page = (u8[hdr] == 0x0D) & (8 + 2 * ncell <= ps)
        if not good_page.all():
            self.lost_pages += int((~good_page).sum())
            base, hdr, ncell = base[good_page], hdr[good_page], ncell[good_page]
        if ncell.sum() == 0:
            return
        maxc = int(ncell.max())
        j = np.arange(maxc)
        mask = j[None, :] < ncell[:, None]
        pp = (hdr[:, None] + 8 + 2 * j[None, :])[mask]
        ptr = u8[pp].astype(np.int64) * 256 + u8[pp + 1]
        cbase = np.repeat(base, ncell)
        cell = cbase + ptr
        inside = (ptr >= 8) & (ptr < ps - 4)
        # Cell layout: payload size, rowid, record header (size, 4 serial types), values.
        p, n1 = _varints(u8, cell)
        rowid, n2 = _varints(u8, cell + n1)
        rec = cell + n1 + n2
        hs, s0, s1, s2, s3, fits = _record_headers(u8, rec)
        ints = np.array([1, 2, 3, 4, 5, 6, 8, 9])
        fast = (inside & fits & (s0 == 0) & np.isin(s1, ints)
                & np.isin(s2, ints) & (s3 >= 12) & (s3 % 2 == 0) & (p <= self.usable - 35))
        v1 = rec + hs
        v2 = v1 + _SERIAL_SIZE[np.where(fast, s1, 0)]
        v3 = v2 + _SERIAL_SIZE[np.where(fast, s2, 0)]
        blob_len = (s3 - 12) // 2
        fast &= (v3 + blob_len <= cbase + ps)
        order = rowid  # ties in receive time keep rowid order, as ORDER BY timestamp, id
        if not fast.all():
            for i in np.nonzero(~fast)[0].tolist():
                self._slow_cell(int(cell[i]) + shift, int(cbase[i]) + shift, wanted, coll)
        topic = _be_ints(u8, v1, np.where(fast, s1, 8))
        keep = fast & np.isin(topic, wanted)
        if not keep.any():
            return
        stamp = _be_ints(u8, v2[keep], s2[keep])
        off, length, order = v3[keep], blob_len[keep], order[keep]
        for ln in np.unique(length):
            sel = length == ln
            ok, t, data = _decode_at(u8, off[sel], int(ln), ros1=coll.ros1)
            if coll.force_generic:
                ok[:] = False
            for i in np.nonzero(~ok)[0].tolist():
                o = int(off[sel][i]) + shift
                t[i], data[i] = coll._generic(bytes(self.mm[o:o + int(ln)]))
            coll.parts.append((order[sel], stamp[sel], t, data))

    def _slow_cell(self, cell, page_base, wanted, coll):
        if not page_base <= cell < page_base + self.page_size - 4:
            self.lost_pages += 1
            return
        try:
            order, payload = self._payload(cell, page_base)
            vals = self._record(payload)
        except (_Unsupported, IndexError, struct.error):
            self.lost_pages += 1
            return
        if len(vals) == 4 and vals[1] in wanted.tolist() and isinstance(vals[3], bytes):
            stamp, blob = int(vals[2]), vals[3]
            t, row = coll._generic(blob)
            coll.parts.append((np.array([order]), np.array([stamp]), np.array([t]),
                               row.reshape(1, 6)))


# ----------------------------------------------------------------------------------------------
# Direct reading of ROS 1 bags (format 2.0, http://wiki.ros.org/Bags/Format/2.0)
#
# rosbags' ROS 1 reader yields about 150-200 k raw messages/s and needs the index at the end of
# the file; scanning the chunks directly slices runs of equal message records with one numpy
# view (as for MCAP) and also reads the complete chunks of a bag cut short while recording.

_ROS1_IMU_MD5 = '6a62c6daae103f4ff57a132d6f95cec2'


def _ros1_fields(buf, pos, end):
    """Parse a ROS 1 record header (``len name=value`` fields) into {name: bytes}."""
    fields = {}
    while pos + 4 <= end:
        (n,) = struct.unpack_from('<I', buf, pos)
        pos += 4
        if pos + n > end:
            raise ValueError('header field overruns its record')
        raw = bytes(buf[pos:pos + n])
        key, sep, value = raw.partition(b'=')
        if not sep:
            raise ValueError('header field without =')
        fields[key.decode('ascii', 'replace')] = (value, pos + len(key) + 1)
        pos += n
    return fields


class _Ros1Scan:
    """Walk the chunks of a ROS 1 bag, collecting the messages of the wanted Imu connections."""

    def __init__(self, path, topic=None, collect=True, force_generic=False):
        self.path = str(path)
        self.topic = topic
        self.collect = collect
        self.force_generic = force_generic
        self.conns = {}  # conn id -> (topic, type, md5)
        self.counts = defaultdict(int)
        self.collectors = {}
        self.warnings = []
        self.unsupported = False

    def run(self):
        """Scan the file up to its index section."""
        with open(self.path, 'rb') as f:
            size = f.seek(0, 2)
            f.seek(0)
            if f.read(len(ROS1_MAGIC)) != ROS1_MAGIC:
                raise InputError(self.path, 'not a ROS 1 bag (bad magic line)')
            mm = _map_file(f)
        buf = memoryview(mm)
        try:
            self._walk(buf, len(ROS1_MAGIC), size, top=True)
        except (struct.error, ValueError, IndexError, KeyError) as err:
            self.warnings.append(f'malformed ROS 1 record ({_one_line(err)}): '
                                 'rest of the file skipped')
        finally:
            try:
                buf.release()
                mm.close()
            except BufferError:
                pass  # a numpy view still refers to the map; the GC frees it

    def _walk(self, buf, pos, end, top):
        u8 = np.frombuffer(buf, dtype=np.uint8, count=end) if self.collect else None
        unpack_i = struct.Struct('<I').unpack_from
        index_pos = end
        backoff = 0
        where = 'file' if top else 'chunk'
        while pos < min(end, index_pos):
            if end - pos < 4:
                self._truncated(pos, end, where)
                return
            (hlen,) = unpack_i(buf, pos)
            hend = pos + 4 + hlen
            if hend + 4 > end:
                self._truncated(pos, end, where)
                return
            (dlen,) = unpack_i(buf, hend)
            rec_end = hend + 4 + dlen
            if rec_end > end:
                if top:
                    self._partial_chunk(buf, pos, hend, end)
                else:
                    self._truncated(pos, end, where)
                return
            try:
                fields = _ros1_fields(buf, pos + 4, hend)
                op = fields['op'][0][:1]
            except (ValueError, KeyError):
                self.warnings.append(f'bad record header at byte {pos}: rest of {where} skipped')
                return
            if op == b'\x02':
                cid = struct.unpack('<I', fields['conn'][0])[0]
                self.counts[cid] += 1
                if self.collect and self._wanted(cid):
                    coll = self._collector(cid)
                    tpos = fields['time'][1] - pos
                    stride = rec_end - pos
                    kmax = (end - pos) // stride
                    if backoff == 0 and kmax > 1:
                        block = u8[pos:pos + kmax * stride].reshape(kmax, stride)
                        # Same header bytes (length, fields, connection) except the time value.
                        same = ((block[:, :tpos] == block[0, :tpos]).all(axis=1)
                                & (block[:, tpos + 8:hend + 4 - pos]
                                   == block[0, tpos + 8:hend + 4 - pos]).all(axis=1))
                        k = kmax if same.all() else int(np.argmin(same))
                        if k > 1:
                            tt = np.ascontiguousarray(block[:k, tpos:tpos + 8]).view('<u4')
                            log_time = tt[:, 0].astype(np.int64) * 1_000_000_000 + tt[:, 1]
                            coll.add_rows(log_time, block[:k, hend + 4 - pos:])
                            self.counts[cid] += k - 1
                            pos += k * stride
                            backoff = 0 if k >= 8 else 32
                            continue
                        backoff = 32
                    elif backoff:
                        backoff -= 1
                    sec, nsec = struct.unpack('<II', fields['time'][0][:8])
                    coll.add_one(sec * 1_000_000_000 + nsec, bytes(buf[hend + 4:rec_end]))
            elif op == b'\x05' and top:
                self._chunk(buf, fields, hend + 4, rec_end, pos)
            elif op == b'\x07':
                self._connection(buf, fields, hend + 4, rec_end)
            elif op == b'\x03' and top:
                ipos = struct.unpack('<Q', fields['index_pos'][0][:8])[0]
                if ipos:
                    index_pos = ipos
                    if ipos > end:
                        self.warnings.append(f'file truncated at byte {end} (index expected at '
                                             f'byte {ipos}): read the complete chunks')
                        index_pos = end
            pos = rec_end
        if top and index_pos == end and not self.warnings:
            self.warnings.append('bag has no index (recording not closed?): read all chunks')

    def _wanted(self, cid):
        c = self.conns.get(cid)
        if c is None or c[1] not in _IMU_TYPES:
            return False
        if c[2] != _ROS1_IMU_MD5:
            self.unsupported = True  # another Imu definition: leave it to rosbags
            return False
        return self.topic is None or c[0] == self.topic

    def _collector(self, cid):
        # Keyed by topic: several connections of one topic merge in receive-time order.
        topic = self.conns[cid][0]
        if topic not in self.collectors:
            self.collectors[topic] = _Collector(True, _noetic_deserialize, self.force_generic)
        return self.collectors[topic]

    def _connection(self, buf, fields, start, end):
        cid = struct.unpack('<I', fields['conn'][0][:4])[0]
        topic = fields['topic'][0].decode('utf-8', 'replace')
        data = _ros1_fields(buf, start, end)
        typ = data.get('type', (b'', 0))[0].decode('utf-8', 'replace')
        if typ.count('/') == 1:
            typ = typ.replace('/', '/msg/')
        md5 = data.get('md5sum', (b'', 0))[0].decode('ascii', 'replace')
        self.conns.setdefault(cid, (topic, typ, md5))

    def _truncated(self, pos, end, where):
        self.warnings.append(f'{where} truncated at byte {pos} of {end}: rest skipped')

    def _chunk(self, buf, fields, start, end, pos):
        try:
            comp = fields['compression'][0].decode('ascii')
            (usize,) = struct.unpack('<I', fields['size'][0][:4])
            if comp == 'none':
                if end - start != usize:
                    raise ValueError('chunk size mismatch')
                raw = None
            elif comp == 'bz2':
                import bz2
                raw = bz2.decompress(buf[start:end])
            elif comp == 'lz4':
                raw = _lz4_decompress(buf[start:end])
            else:
                raise ValueError(f'unknown compression {comp!r}')
            if raw is not None and len(raw) != usize:
                raise ValueError('chunk size mismatch')
        except Exception as err:  # any decoding failure means this chunk is unreadable
            self.warnings.append(f'corrupt chunk at byte {pos} skipped ({err})')
            return
        try:
            if raw is None:
                self._walk(buf[start:end], 0, usize, top=False)
            else:
                self._walk(memoryview(raw), 0, usize, top=False)
        except (struct.error, ValueError, IndexError, KeyError) as err:
            self.warnings.append(f'malformed record in the chunk at byte {pos} '
                                 f'({_one_line(err)}): rest of that chunk skipped')

    def _partial_chunk(self, buf, pos, hend, end):
        """Read the complete records of an uncompressed chunk cut off by the end of the file."""
        try:
            fields = _ros1_fields(buf, pos + 4, hend)
            ok = fields['op'][0][:1] == b'\x05' and fields['compression'][0] == b'none'
        except (ValueError, KeyError):
            ok = False
        if not ok:
            self._truncated(pos, end, 'file')
            return
        before = len(self.warnings)
        self._walk(buf[hend + 4:end], 0, end - hend - 4, top=False)
        del self.warnings[before:]
        self.warnings.append(f'file truncated at byte {end} inside the chunk starting at byte '
                             f'{pos}: its complete messages were read, the rest is lost')


def _noetic_deserialize(blob):
    """Deserialize one ROS 1 Imu with the Noetic typestore (built once, on first use)."""
    global _NOETIC_STORE
    if _NOETIC_STORE is None:
        from rosbags.typesys import get_typestore, Stores
        _NOETIC_STORE = get_typestore(Stores.ROS1_NOETIC)
    return _NOETIC_STORE.deserialize_ros1(blob, IMU_TYPE)


_NOETIC_STORE = None


def _read_ros1_scan(where, p, topic, force_generic=False):
    """Read a ROS 1 bag with the chunk scanner; None if it holds a non-standard Imu type."""
    scan = _Ros1Scan(p, topic, force_generic=force_generic)
    scan.run()
    if scan.unsupported:
        return None
    topics = {}
    for cid, (name, typ, _) in scan.conns.items():
        t0, n = topics.get(name, (typ, 0))
        topics[name] = (t0, n + scan.counts.get(cid, 0))
    if scan.warnings and not any(typ in _IMU_TYPES for typ, _ in topics.values()):
        raise InputError(where, f'damaged ROS 1 bag, no Imu data readable ({scan.warnings[0]})')
    chosen = _choose_topic(where, topics, topic)
    if chosen not in scan.collectors:
        return chosen, np.zeros(0), np.zeros((0, 6)), scan.warnings
    coll = scan.collectors[chosen]
    t, d = coll.result()
    return chosen, t, d, scan.warnings + coll.warnings()
