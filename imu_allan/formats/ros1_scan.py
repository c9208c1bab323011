"""
Direct reading of ROS 1 bags (format 2.0, http://wiki.ros.org/Bags/Format/2.0).

rosbags' ROS 1 reader yields about 150-200 k raw messages/s and needs the index at the end of
the file; scanning the chunks (none/bz2/lz4) directly slices runs of equal message records with
one numpy view (as for MCAP) and also reads the complete chunks of a bag cut short while
recording.
"""

from functools import partial
import struct

import numpy as np

from .collector import Collector
from .imu_cdr import deserialize, IMU_TYPES, MIN_IMU_BYTES
from .mcap_scan import lz4_decompress
from .scan_common import choose_topic, ChunkScan, map_file, one_line, Passed, Runs
from ..errors import InputError

ROS1_MAGIC = b'#ROSBAG V2.0\n'

_ROS1_IMU_MD5 = '6a62c6daae103f4ff57a132d6f95cec2'
#: Fewest bytes of a message record before its data: header length, the op (4 + 'op=' + 1),
#: conn (4 + 'conn=' + 4) and time (4 + 'time=' + 8) fields, data length.
_MESSAGE_HEADER = 4 + 8 + 13 + 17 + 4


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


class Ros1Scan(ChunkScan):
    """Walk the chunks of a ROS 1 bag, collecting the messages of the wanted Imu connections."""

    def __init__(self, path, topic=None, collect=True, force_generic=False):
        super().__init__(path, topic, collect, force_generic)
        self.conns = {}  # conn id -> (topic, type, md5)
        self.unsupported = False
        self.chunk_info = {}  # chunk position -> {conn id: message count}, from the index

    def run(self):
        """Scan the file up to its index section."""
        with open(self.path, 'rb') as f:
            size = f.seek(0, 2)
            f.seek(0)
            if f.read(len(ROS1_MAGIC)) != ROS1_MAGIC:
                raise InputError(self.path, 'not a ROS 1 bag (bad magic line)')
            mm = map_file(f)
        self._size, self._passed = size, Passed(mm)
        buf = memoryview(mm)
        try:
            self._read_index(buf, size)
            self._walk(buf, len(ROS1_MAGIC), size, top=True)
        except (struct.error, ValueError, IndexError, KeyError) as err:
            self.warnings.append(f'malformed ROS 1 record ({one_line(err)}): '
                                 'rest of the file skipped')
        finally:
            try:
                buf.release()
                mm.close()
            except BufferError:
                pass  # a numpy view still refers to the map; the GC frees it

    def _read_index(self, buf, size):
        """
        Pre-read the connections and chunk infos of the index section, if it is intact.

        With them a damaged first chunk (which holds the connection records) does not cost the
        intact chunks, and a skipped chunk's lost messages can be counted.
        """
        try:
            pos = len(ROS1_MAGIC)
            (hlen,) = struct.unpack_from('<I', buf, pos)
            fields = _ros1_fields(buf, pos + 4, pos + 4 + hlen)
            if fields['op'][0][:1] != b'\x03':
                return
            pos = struct.unpack('<Q', fields['index_pos'][0][:8])[0]
            while len(ROS1_MAGIC) < pos and pos + 8 <= size:
                (hlen,) = struct.unpack_from('<I', buf, pos)
                hend = pos + 4 + hlen
                (dlen,) = struct.unpack_from('<I', buf, hend)
                rec_end = hend + 4 + dlen
                if rec_end > size:
                    return
                fields = _ros1_fields(buf, pos + 4, hend)
                op = fields['op'][0][:1]
                if op == b'\x07':
                    self._connection(buf, fields, hend + 4, rec_end)
                elif op == b'\x06':
                    (chunk_pos,) = struct.unpack('<Q', fields['chunk_pos'][0][:8])
                    pairs = np.frombuffer(buf[hend + 4:rec_end], dtype='<u4').reshape(-1, 2)
                    self.chunk_info[chunk_pos] = dict(pairs.tolist())
                pos = rec_end
        except (struct.error, ValueError, IndexError, KeyError):
            pass  # a damaged index only means no help for the walk

    def _lost(self, pos, read):
        """Words on the Imu messages a damaged chunk at ``pos`` lost (``read`` were read)."""
        if pos not in self.chunk_info:
            return ''
        order = sorted(self.chunk_info)
        wanted = sum(n for c, n in self.chunk_info[pos].items() if self._wanted(c))
        return (f' (chunk {order.index(pos) + 1} of {len(order)}: {wanted - read} of its '
                f'{wanted} Imu message(s) lost)')

    def _walk(self, buf, pos, end, top):
        u8 = np.frombuffer(buf, dtype=np.uint8, count=end) if self.collect else None
        unpack_i = struct.Struct('<I').unpack_from
        index_pos = end
        runs = Runs()
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
                    tpos, data = fields['time'][1] - pos, hend + 4 - pos
                    # a run: the same header bytes (length, fields, connection) but the time
                    block = runs.take(u8, pos, end, rec_end - pos, ((0, tpos), (tpos + 8, data)))
                    if block is not None:
                        tt = np.ascontiguousarray(block[:, tpos:tpos + 8]).view('<u4')
                        log_time = tt[:, 0].astype(np.int64) * 1_000_000_000 + tt[:, 1]
                        # a nanosecond field of 1e9 or more is no time: damaged record
                        coll.add_rows(log_time, block[:, data:], bad=tt[:, 1] >= 1_000_000_000)
                        self.counts[cid] += block.shape[0] - 1
                        pos += block.shape[0] * (rec_end - pos)
                        continue
                    sec, nsec = struct.unpack('<II', fields['time'][0][:8])
                    coll.add_one(sec * 1_000_000_000 + nsec if nsec < 1_000_000_000 else None,
                                 bytes(buf[hend + 4:rec_end]))
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
        if c is None or c[1] not in IMU_TYPES:
            return False
        if c[2] != _ROS1_IMU_MD5:
            self.unsupported = True  # another Imu definition: leave it to rosbags
            return False
        return self.topic is None or c[0] == self.topic

    def _collector(self, cid):
        # Keyed by topic: several connections of one topic merge in receive-time order.
        topic = self.conns[cid][0]
        if topic not in self.collectors:
            self.collectors[topic] = Collector(
                True, partial(deserialize, ros1=True), self.force_generic,
                capacity=self._size // (MIN_IMU_BYTES + _MESSAGE_HEADER))
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
                raw = lz4_decompress(buf[start:end])
            else:
                raise ValueError(f'unknown compression {comp!r}')
            if raw is not None and len(raw) != usize:
                raise ValueError('chunk size mismatch')
        except Exception as err:  # any decoding failure means this chunk is unreadable
            self.warnings.append(f'corrupt chunk at byte {pos} skipped ({one_line(err)})'
                                 + self._lost(pos, 0))
            return
        before = self._wanted_count()
        n_warnings = len(self.warnings)
        if raw is None:
            self._walk_chunk(buf, start, end, pos)
        else:
            self._walk_chunk(memoryview(raw), 0, usize, pos)
        if len(self.warnings) > n_warnings:  # the chunk walk stopped early: say what it cost
            self.warnings[-1] += self._lost(pos, self._wanted_count() - before)
        # everything before this chunk's end is passed (the index records between chunks too)
        self._passed.upto(end)

    def _wanted_count(self):
        return sum(n for c, n in self.counts.items() if self._wanted(c))

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
        self._walk_partial(buf, hend + 4, pos, end)


def read_ros1_scan(where, p, topic, force_generic=False):
    """Read a ROS 1 bag with the chunk scanner; None if it holds a non-standard Imu type."""
    scan = Ros1Scan(p, topic, force_generic=force_generic)
    scan.run()
    if scan.unsupported:
        return None
    topics = {}
    for cid, (name, typ, _) in scan.conns.items():
        t0, n = topics.get(name, (typ, 0))
        topics[name] = (t0, n + scan.counts.get(cid, 0))
    if scan.warnings and not any(typ in IMU_TYPES for typ, _ in topics.values()):
        raise InputError(where, f'damaged ROS 1 bag, no Imu data readable ({scan.warnings[0]})')
    chosen = choose_topic(where, topics, topic)
    if chosen not in scan.collectors:
        return chosen, np.zeros(0), np.zeros((0, 6)), scan.warnings, ''
    coll = scan.collectors[chosen]
    t, d = coll.result()
    return chosen, t, d, scan.warnings + coll.warnings(), coll.frame_id
