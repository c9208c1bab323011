"""
Direct scanning of MCAP files for ``sensor_msgs/Imu`` messages.

Handing over one raw message at a time (``AnyReader``: about 500 k/s for MCAP) would cap the
fast path below 1 M messages/s, so records and chunks are walked directly (zstd/lz4 chunk
compression, CRC checked) and runs of equal message records inside a chunk are sliced out
with one numpy view. Works without the summary section: a truncated file gives its complete
chunks (and the complete records of an uncompressed chunk cut short), a corrupt compressed
chunk is skipped.

Chunks without a CRC cannot show a flipped value, but their structure can show damage, and
a strict reader (the ``mcap`` package's) refuses it; each such fact is a counted warning
(:meth:`McapScan.structure_warnings`): messages on a channel id no Channel record declares, a
Channel naming a schema id no Schema record declares or declared twice differently, records a
chunk may not hold (only Schema, Channel and Message), and message counts that differ from
the summary's (the Statistics record, else the chunks' message indexes).
"""

from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
import os
import struct
import sys
import threading

try:  # 3-4x zlib's speed (carry-less multiply); optional
    from isal.isal_zlib import crc32
except ImportError:
    from zlib import crc32  # (binascii's holds the GIL: zlib's lets threads check chunks)

import numpy as np

from .collector import Collector
from .imu_cdr import deserialize, IMU_TYPES, MIN_IMU_BYTES
from .scan_common import ChunkScan, compiled_walks, map_file, one_line, Passed, Runs
from ..errors import InputError

MCAP_MAGIC = b'\x89MCAP0\r\n'


def _zstd_decompress(data):
    try:
        from compression import zstd  # Python >= 3.14
    except ImportError:
        from backports import zstd
    return zstd.decompress(data)


def lz4_decompress(data):
    from lz4.frame import decompress
    return decompress(data)


_DECOMPRESS = {'': bytes, 'zstd': _zstd_decompress, 'lz4': lz4_decompress}


def decompress_chunk(compression, data, size):
    """Return the records of a chunk (bytes); ValueError for unknown compression or size."""
    if compression not in _DECOMPRESS:
        raise ValueError(f'unknown chunk compression {compression!r}')
    raw = _DECOMPRESS[compression](data)
    if len(raw) != size:
        raise ValueError('chunk size mismatch')
    return raw


def open_chunk(buf, pos, rec_end):
    """
    Return the records of the Chunk record at byte ``pos``: ``(buffer, start, size, has_crc)``.

    Decompressed and checked against the chunk's CRC (when its writer stored one); the records
    of an uncompressed chunk are returned in place (``buf`` and their offset).  Raises
    ValueError (or the decompressor's error) for any damage.
    """
    _t0, _t1, usize = struct.unpack_from('<QQQ', buf, pos + 9)
    (crc,) = struct.unpack_from('<I', buf, pos + 33)
    comp, p = McapScan._string(buf, pos + 37)
    (csize,) = struct.unpack_from('<Q', buf, p)
    p += 8
    if p + csize > rec_end or comp not in _DECOMPRESS:
        raise ValueError('bad chunk header')
    if comp:
        inner, base = memoryview(decompress_chunk(comp, buf[p:p + csize], usize)), 0
    else:
        if csize != usize:
            raise ValueError('chunk size mismatch')
        inner, base = buf, p
    if crc and crc32(inner[base:base + usize]) != crc:
        raise ValueError('chunk checksum mismatch')
    return inner, base, usize, bool(crc)


#: Chunks decompressed and checked ahead of the walk (:meth:`McapScan._open_chunk`).
AHEAD = 4

_MCAP_OPS = frozenset(range(0x01, 0x11))  # record opcodes of MCAP v0 (0x80-0xFF: private)
#: The records a chunk may hold (MCAP specification, Chunk): Schema, Channel, Message.
_CHUNK_OPS = frozenset((0x03, 0x04, 0x05))


#: Bytes of an MCAP Message record before its data: opcode, length, channel id, sequence,
#: log time and publish time.
MESSAGE_HEADER = 1 + 8 + 2 + 4 + 8 + 8

#: File size from which the compiled walk (:func:`.bag_kernels.mcap_walk`) reads the chunks
#: even when numba is not imported yet: about 0.6 M Imu messages, from where ``analyze`` loads
#: numba for the Allan deviation anyway (as ``sqlite_pages.COMPILED_MIN_PAGES``).
COMPILED_MIN_BYTES = 200 << 20


class McapScan(ChunkScan):
    """
    Walk the records of an MCAP file, collecting the messages of the wanted Imu channels.

    Works without the summary section, so a truncated file yields what precedes the damage.
    """

    def __init__(self, path, topic=None, collect=True, force_generic=False):
        super().__init__(path, topic, collect, force_generic)
        self.schemas = {}  # id -> name
        self.channels = {}  # id -> (topic, type name, encoding)
        self.summary_counts = None  # {channel id: messages} the summary states, when it does
        self.foreign_records = defaultdict(int)  # opcode -> records a chunk may not hold
        self.channel_problems = []  # Channel records that contradict the declarations
        self.complete = False
        self.chunk_offsets = []
        self.chunk_counts = {}  # chunk offset -> {channel id: messages}, from the summary
        self.chunks_without_crc = 0  # chunks whose writer stored no CRC: content unverifiable
        self._kernel = None  # the compiled chunk walk, when it is used
        self._kernel_counts = None  # messages per channel id that it walked
        self._role_cache = (None, None, None)  # channels, role per id, a decoded id (_roles)
        self._scratch = (np.empty((3, 0), dtype=np.int64), np.empty(0, dtype=bool))
        self._pool = None  # threads opening the chunks ahead of the walk
        self._ahead = {}  # chunk offset -> future of open_chunk
        self._next = 0  # index in chunk_offsets of the next chunk to open ahead

    def _wanted(self, cid):
        ch = self.channels.get(cid)
        if ch is None or ch[1] not in IMU_TYPES:
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
            mm = map_file(f)
        self._size, self._passed = size, Passed(mm)
        try:
            buf = memoryview(mm)
            try:
                self._read_summary(buf, size)
                if self.collect and not self.force_generic:
                    self._load_kernel()
                if len(self.chunk_offsets) > 1:
                    self._pool = ThreadPoolExecutor(min(2, os.cpu_count() or 1))
                self._walk(buf, 8, size, top=True)
            except (struct.error, ValueError, IndexError, KeyError) as err:
                self.warnings.append(f'malformed MCAP record ({one_line(err)}): '
                                     'rest of the file skipped')
            finally:
                if self._pool is not None:  # done with the map before it is released
                    self._pool.shutdown(cancel_futures=True)
                    self._pool, self._ahead = None, {}
                if self._kernel is not None:
                    for cid in np.flatnonzero(self._kernel_counts).tolist():
                        self.counts[cid] += int(self._kernel_counts[cid])
                self.warnings += self.structure_warnings()
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
        """
        Pre-read schemas, channels and chunk offsets from the summary, if the footer is intact.

        With them a damaged first chunk (which holds the channel definitions) or a damaged
        record header does not cost the rest of the file: the walk resumes at the next chunk.
        """
        self.chunk_offsets = []
        self.chunk_counts = {}
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
                    chunk = struct.unpack_from('<Q', buf, pos + 9 + 16)[0]
                    self.chunk_offsets.append(chunk)
                    self.chunk_counts[chunk] = self._index_counts(buf, pos + 41)
                elif op == 0x0B:
                    self.summary_counts = self._statistics_counts(buf, pos + 9, pos + 9 + length)
                pos += 9 + length
        except (struct.error, IndexError, ValueError):
            pass  # a damaged summary only means no help for the walk
        self.chunk_offsets.sort()

    @staticmethod
    def _statistics_counts(buf, pos, end):
        """{channel id: messages} of a Statistics record's channel_message_counts."""
        (size,) = struct.unpack_from('<I', buf, pos + 42)  # after the counts and the times
        if pos + 46 + size > end or size % 10:
            raise ValueError('bad Statistics record')
        return dict(struct.unpack_from('<HQ', buf, pos + 46 + 10 * k) for k in range(size // 10))

    @staticmethod
    def _index_counts(buf, pos):
        """{channel id: messages} of a chunk, from the Message Index records its index names."""
        counts = {}
        try:
            (size,) = struct.unpack_from('<I', buf, pos)
            for k in range(size // 10):
                cid, offset = struct.unpack_from('<HQ', buf, pos + 4 + 10 * k)
                if buf[offset] == 0x07:
                    counts[cid] = struct.unpack_from('<I', buf, offset + 11)[0] // 16
        except (struct.error, IndexError):
            pass  # a damaged index: the loss is then not counted
        return counts

    def _lost(self, pos):
        """Words on the Imu messages lost with the chunk at byte ``pos`` (from the index)."""
        if pos not in self.chunk_counts:
            return ''
        n = sum(c for cid, c in self.chunk_counts[pos].items() if self._wanted(cid))
        k = self.chunk_offsets.index(pos) + 1
        return f' (chunk {k} of {len(self.chunk_offsets)}: {n} Imu message(s) lost)'

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
        runs = Runs()
        where = 'file' if top else 'chunk'
        kernel = None if top else self._kernel
        views = None if kernel is None else kernel.byte_views(u8, kernel.MCAP_VIEWS)
        while pos < end:
            if views is not None:
                # The compiled walk takes the Message records it can; this loop takes the
                # record it stopped at (or returns at the end).
                pos = self._compiled_walk(u8, views, pos, end)
                if pos >= end:
                    return
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
                    # a run: the same opcode, length and channel id as this record
                    block = runs.take(u8, pos, end, 9 + length, ((0, 11),))
                    if block is not None:
                        # u64 on disk: add_rows skips and counts those beyond int64
                        log_time = np.ascontiguousarray(
                            block[:, 15:23]).view('<u8')[:, 0].astype(np.uint64)
                        coll.add_rows(log_time, block[:, 31:])
                        self.counts[cid] += block.shape[0] - 1
                        pos += block.shape[0] * (9 + length)
                        continue
                    (log_time,) = unpack_q(buf, pos + 15)
                    coll.add_one(log_time, bytes(buf[pos + 31:rec_end]))
            elif op == 0x06 and top:
                self._chunk(buf, pos, rec_end)
            elif op == 0x03:
                (sid,) = unpack_h(buf, pos + 9)
                name, _ = self._string(buf, pos + 11)
                self.schemas[sid] = name
            elif op == 0x04:
                self._channel(buf, pos)
            elif not top and op not in _CHUNK_OPS:
                self.foreign_records[op] += 1  # (a damaged opcode hides the record it was)
            elif op in (0x0F, 0x02) and top:
                self.complete = True  # DataEnd or Footer: the summary follows
                return
            pos = rec_end
        if top:
            # Records ended cleanly without a DataEnd/Footer: the writer did not finish.
            self.warnings.append('MCAP file has no end marker (recording not closed?); '
                                 'read all complete records')

    def _channel(self, buf, pos):
        """
        Take the Channel record at ``pos``; one that contradicts the declarations is noted.

        The first declaration of an id stands (the summary's, read first, or the data's): a
        second that differs, or one naming an undeclared schema id, is damage.
        """
        (cid,) = struct.unpack_from('<H', buf, pos + 9)
        (sid,) = struct.unpack_from('<H', buf, pos + 11)
        topic, p = self._string(buf, pos + 13)
        enc, _ = self._string(buf, p)
        if sid and sid not in self.schemas:
            self.channel_problems.append(f'channel {cid} ({topic[:60]}) names schema id {sid}, '
                                         'which no Schema record declares')
            self.channels.setdefault(cid, (topic, '', enc))
            return
        channel = (topic, self.schemas.get(sid, ''), enc)
        known = self.channels.setdefault(cid, channel)
        if known != channel:
            self.channel_problems.append(f'channel {cid} declared as {known[0][:60]} and again '
                                         f'differently as {topic[:60]}: the first kept')

    def structure_warnings(self):
        """
        Return one counted warning per kind of damaged structure the walk met (module docstring).

        Each is damage that changes what is read without any CRC to catch it (a flipped channel
        id or opcode loses that message), and that a strict reader refuses.
        """
        out = []
        undeclared = {cid: n for cid, n in self.counts.items() if cid not in self.channels}
        if undeclared:
            ids = ', '.join(str(c) for c in sorted(undeclared)[:5])
            out.append(f'{sum(undeclared.values())} message(s) on channel id(s) {ids} that no '
                       'Channel record declares (damaged channel ids): not read')
        if self.foreign_records:
            ops = ', '.join(f'0x{op:02X}' for op in sorted(self.foreign_records)[:5])
            out.append(f'{sum(self.foreign_records.values())} record(s) inside chunks with an '
                       f'opcode a chunk cannot hold ({ops}; damaged record headers): skipped')
        out += [f'damaged Channel record: {p}' for p in self.channel_problems[:3]]
        stated = self.summary_counts
        if stated is None and self.chunk_counts and \
                all(self.chunk_counts.get(o) for o in self.chunk_offsets):
            stated = defaultdict(int)
            for counts in self.chunk_counts.values():
                for cid, n in counts.items():
                    stated[cid] += n
        if stated is not None and self.complete and not self.warnings:  # (else: loss said)
            differ = sorted(c for c in set(stated) | set(self.channels)
                            if stated.get(c, 0) != self.counts.get(c, 0))
            if differ:
                words = '; '.join(f'{self.channels.get(c, (f"channel {c}",))[0][:60]}: '
                                  f'{stated.get(c, 0)} stated, {self.counts.get(c, 0)} found'
                                  for c in differ[:3])
                out.append(f'the summary counts other messages than the file holds ({words})')
        return out

    def _load_kernel(self):
        """
        Load the compiled walk (:func:`.scan_common.compiled_walks`), if it is used for this file.

        Importing numba holds the GIL for 0.3-0.5 s and leaves the other core idle; when the
        summary names the one topic to read, its arrays are written to meanwhile on a thread
        (``Collector.prefault``): the first write to each page is the operating system's work
        (0.03-0.05 s for the 200 MB of 10 h where fresh memory is quick to map, up to 0.7 s
        measured on this project's VM).
        """
        large = self._size >= COMPILED_MIN_BYTES
        warm = None
        if large and 'numba' not in sys.modules:
            wanted = [c for c in sorted(self.channels) if self._wanted(c)]
            indexed = any(counts.get(c) for counts in self.chunk_counts.values()
                          for c in wanted)
            if indexed and len({self.channels[c][0] for c in wanted}) == 1:
                warm = threading.Thread(target=self._collector(wanted[0]).prefault)
                warm.start()
        try:
            self._kernel = compiled_walks(large)
        finally:
            if warm is not None:
                warm.join()   # before the walk writes there
        if self._kernel is not None:
            self._kernel_counts = np.zeros(1 << 16, dtype=np.int64)

    def _compiled_walk(self, u8, views, pos, end):
        """Walk the Message records of u8[pos:end] compiled; return where the walk stopped."""
        kernel = self._kernel
        role, cid = self._roles()
        room = (end - pos) // MESSAGE_HEADER + 1 if cid is not None else 0
        coll = self.collectors.get(self.channels[cid][0]) if cid is not None else None
        slots = coll.reserved(room) if coll is not None else None
        t, data = slots if slots is not None else (np.empty(room), np.empty((room, 6)))
        if self._scratch[1].size < room:  # kept between chunks: no allocation churn per chunk
            self._scratch = np.empty((3, room), dtype=np.int64), np.empty(room, dtype=bool)
        log_time, off, length = self._scratch[0][:, :room]
        ok = self._scratch[1][:room]
        pos, kept = kernel.mcap_walk(u8, *views, pos, end, role, self._kernel_counts, log_time,
                                     off, length, ok, t, data)
        if kept:
            def blob_of(i):
                return bytes(u8[off[i]:off[i] + length[i]])
            self._collector(cid).add_decoded(log_time[:kept].copy(), t[:kept], data[:kept],
                                             ok[:kept], blob_of)
        return pos

    def _roles(self):
        """
        Return what the compiled walk does per channel id, and one channel of what it decodes.

        It decodes the first wanted topic's channels and counts the other channels' messages;
        the channels of other wanted topics are left to :meth:`_walk`.  Kept until a channel
        record changes the channels.
        """
        key = tuple(self.channels.items())
        if self._role_cache[0] != key:
            kernel = self._kernel
            role = np.full(1 << 16, kernel.COUNT, dtype=np.int8)
            first = None
            for cid in sorted(self.channels):
                if self._wanted(cid):
                    first = cid if first is None else first
                    same = self.channels[cid][0] == self.channels[first][0]
                    role[cid] = kernel.DECODE if same else kernel.LEAVE
            self._role_cache = key, role, first
        return self._role_cache[1:]

    @staticmethod
    def _string(buf, pos):
        (n,) = struct.unpack_from('<I', buf, pos)
        return bytes(buf[pos + 4:pos + 4 + n]).decode('utf-8', 'replace'), pos + 4 + n

    def _collector(self, cid):
        # Keyed by topic: several channels of one topic merge in receive-time order.
        topic = self.channels[cid][0]
        if topic not in self.collectors:
            # the summary's count of the topic's messages, else a bound from the file size
            indexed = sum(n for counts in self.chunk_counts.values() for c, n in counts.items()
                          if self.channels.get(c, ('',))[0] == topic)
            self.collectors[topic] = Collector(
                False, deserialize, self.force_generic,
                capacity=indexed or self._size // (MIN_IMU_BYTES + MESSAGE_HEADER))
        return self.collectors[topic]

    def _chunk(self, buf, pos, rec_end):
        try:
            inner, base, usize, has_crc = self._open_chunk(buf, pos, rec_end)
            self.chunks_without_crc += not has_crc
        except Exception as err:  # any decoding failure means this chunk is unreadable
            self.warnings.append(f'corrupt chunk at byte {pos} skipped ({err})' + self._lost(pos))
            return
        self._walk_chunk(inner, base, base + usize, pos)  # (uncompressed: in place, no copy)
        # everything before this chunk's end is passed (the message indexes between chunks too)
        self._passed.upto(rec_end)

    def _open_chunk(self, buf, pos, rec_end):
        """
        :func:`open_chunk` for the chunk at ``pos``, done ahead on threads when possible.

        With the summary's chunk offsets, the next :data:`AHEAD` chunks are decompressed and
        checked on two threads while this one walks (the CRC and the decompressors release the
        GIL): the other core does that work.
        """
        if self._pool is None:
            return open_chunk(buf, pos, rec_end)
        for off in [o for o in self._ahead if o < pos]:  # skipped by the walk (damage)
            self._ahead.pop(off).cancel()
        offsets = self.chunk_offsets
        while len(self._ahead) < AHEAD and self._next < len(offsets):
            off = offsets[self._next]
            self._next += 1
            if off <= pos or buf[off] != 0x06:
                continue
            end = off + 9 + struct.unpack_from('<Q', buf, off + 1)[0]
            if end <= self._size:
                self._ahead[off] = self._pool.submit(open_chunk, buf, off, end)
        future = self._ahead.pop(pos, None)
        return open_chunk(buf, pos, rec_end) if future is None else future.result()

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
        self._walk_partial(buf, p, pos, end)
