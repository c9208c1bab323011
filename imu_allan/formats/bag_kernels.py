"""
Compiled walks of rosbag2 files (numba): sqlite3 ``messages`` pages and MCAP chunks.

Both read ``sensor_msgs/Imu`` messages straight from the file's bytes into the caller's
arrays: the receive time, and for little-endian CDR the stamp and the six values
(:func:`decode_imu`, the numbers of the numpy bulk decoder :func:`.imu_cdr.decode_rows`).

* :func:`sqlite_walk`, used by :mod:`.sqlite_pages`: one pass per batch of table-leaf pages
  does what ``SqlitePages._batch`` does in about twenty numpy passes: cell pointers, the
  varints of payload size and rowid, the record header (size and four serial types), the
  checks that make a cell a plain message row on its page, the topic id filter.  Every
  decision is the one the numpy walk takes on the same bytes, including how reads near the
  end of the buffer are clipped.  Cells that are not plain rows (overflow pages, damage) go
  back to the caller's slow path.
* :func:`mcap_walk`, used by :mod:`.mcap_scan`: the numpy walk of ``McapScan._walk`` slices
  runs of equal Message records out of a chunk and decodes them in bulk, about ten numpy
  passes and several copies per run; this reads each Message record once and stops at the
  first record that needs the scanner's judgement (any other record, a message too short for
  its fixed fields, a record running past the end, a channel the caller marked ``LEAVE``):
  the numpy walk takes that record and calls this one again.

The numpy walks stay the readable references: the tests compare both on intact, damaged and
mixed bags.  Blobs the bulk layout does not fit go to the generic deserializer.

One module for all of them because numba's disk cache checks only the source file of the
function it caches: :func:`decode_imu`, inlined into both walks, must live in the same file,
or a change to it would leave stale walks in the cache.  Compiled once per install, as the
Allan kernel (:mod:`imu_allan.core.jit`: module-level functions with ``cache=True``, the
user cache folder where ``__pycache__`` is read-only).
"""

from collections import namedtuple

import numpy as np

from .sqlite_digest import DIGEST_ROWID, DIGEST_TS  # fixed constants: no stale cache
from ..core.jit import jit, UNCACHED

#: Bytes of the 37 float64 at the end of an Imu, and the first byte of a CDR Imu after its
#: frame_id (encapsulation header, sec, nanosec, the string length) - as :mod:`.imu_cdr`.
_TAIL = 37 * 8
_HEAD = 16
#: Offsets in bytes of angular velocity and linear acceleration inside the 37 float64.
_GYRO = 13 * 8
_ACCEL = 25 * 8


def byte_view(u8, dtype):
    """Return the little-endian ``dtype`` values starting at every byte offset of ``u8`` (view)."""
    size = np.dtype(dtype).itemsize
    return np.ndarray(shape=(max(u8.shape[0] - size + 1, 0),), dtype=dtype, buffer=u8,
                      strides=(1,))


def byte_views(u8, dtypes=('<u4', '<f8')):
    """Return the ``dtypes`` at every byte offset of ``u8`` (views; default uint32, float64)."""
    return tuple(byte_view(u8, dtype) for dtype in dtypes)


@jit(nogil=True, inline='always')
def decode_imu(u8, u4, f8, off, length, t, data, k):  # pragma: no cover - compiled
    """
    Decode the blob u8[off:off + length] into t[k] (s) and data[k] (rad/s, m/s^2).

    As :func:`.imu_cdr.decode_rows` for one blob: a little-endian CDR Imu of exactly this
    length gives its stamp (NaN if nanosec >= 1e9) and values; False if the layout does not
    fit (the caller then uses the generic deserializer).  ``u4`` / ``f8``: uint32 / float64
    views of ``u8`` at every byte offset (:func:`byte_views`: unaligned loads).
    """
    if length < _HEAD + _TAIL or u8[off] != 0 or u8[off + 1] != 1:
        return False
    pos = _HEAD + np.int64(u4[off + 12])
    start = pos + (-(pos - 4)) % 8   # CDR aligns from the end of the encapsulation header
    if start + _TAIL != length:
        return False
    sec = np.float64(np.int32(u4[off + 4]))   # int32 seconds
    nsec = np.float64(u4[off + 8])
    t[k] = sec + nsec * 1e-9 if nsec < 1e9 else np.nan
    g = off + start + _GYRO
    a = off + start + _ACCEL
    for j in range(3):
        data[k, j] = f8[g + 8 * j]
        data[k, 3 + j] = f8[a + 8 * j]
    return True


@jit(nogil=True, inline='always')
def _varint(u8, pos, last):  # pragma: no cover - compiled; tested against the numpy walk
    # (value, size) of the SQLite varint at pos; bytes past ``last`` read as byte ``last``, as
    # sqlite_pages._varints does (only cells the checks then refuse ever get there).
    b = np.int64(u8[min(pos, last)])
    if b < 0x80:   # one byte: serial types, header sizes, small rowids
        return b, 1
    v = b & 0x7F
    for k in range(1, 8):
        b = np.int64(u8[min(pos + k, last)])
        v = (v << 7) | (b & 0x7F)
        if b < 0x80:
            return v, k + 1
    return (v << 8) | np.int64(u8[min(pos + 8, last)]), 9


@jit(nogil=True, inline='always')
def _serial_size(st):  # pragma: no cover - compiled
    # Bytes of an integer serial type (1-6, 8 and 9); -1 for any other.
    if st >= 1 and st <= 4:
        return st
    if st == 5:
        return 6
    if st == 6:
        return 8
    if st == 8 or st == 9:
        return 0
    return -1


@jit(nogil=True, inline='always')
def _be_int(u8, pos, st):  # pragma: no cover - compiled
    # Big-endian signed integer of serial type st (1-6, 8: 0, 9: 1).
    if st == 8:
        return np.int64(0)
    if st == 9:
        return np.int64(1)
    size = _serial_size(st)
    v = np.int64(0)
    for j in range(size):
        v = (v << 8) | np.int64(u8[pos + j])
    if size < 8:
        sign = np.int64(1) << (8 * size - 1)
        if v >= sign:
            v -= sign << 1
    return v


@jit(nogil=True, inline='always')
def row_digest(stamp, rowid):  # pragma: no cover - compiled
    # One row's share of a table's digest (as sqlite_digest.row_digests): summed (wrapping)
    # over its rows in any order, and compared with the same sum over its timestamp index.
    return (np.uint64(stamp) * DIGEST_TS) ^ (np.uint64(rowid) * DIGEST_ROWID)


@jit(nogil=True, inline='always')
def _get2(u8, pos):  # pragma: no cover - compiled
    return np.int64(u8[pos]) * 256 + np.int64(u8[pos + 1])


@jit(nogil=True, inline='always')
def cell_size(p, n1, n2, usable):  # pragma: no cover - compiled
    """Return the bytes one table-leaf cell takes on its page, as ``SqlitePages.cell_sizes``."""
    if p < 0 or p >= np.int64(1) << 31:
        return np.int64(-1)
    x = usable - 35
    if p <= x:
        size = n1 + n2 + p
    else:
        m = ((usable - 12) * 32 // 255) - 23
        k = m + (p - m) % (usable - 4)
        size = n1 + n2 + (k if k <= x else m) + 4
    return max(size, np.int64(4))


@jit(nogil=True, inline='always')
def space_adds_up(u8, base, hdr, usable, used):  # pragma: no cover - compiled
    """Return True if a page's space adds up, as ``SqlitePages.space_failures`` (used: cells)."""
    content = _get2(u8, hdr + 5)
    if content == 0:
        content = 65536
    free = np.int64(0)
    fb = _get2(u8, hdr + 1)
    while fb != 0:
        if fb < content or fb + 4 > usable:
            return False
        nxt = _get2(u8, base + fb)
        free += _get2(u8, base + fb + 2)
        if nxt != 0 and nxt <= fb:
            return False
        fb = nxt
    return usable - content == used + free + np.int64(u8[hdr + 7])


#: The output arrays of :func:`sqlite_walk`, one entry per kept row (numba takes it as one
#: argument): rowid, receive time (ns), blob offset and length in the file's bytes, decoded
#: flag, and where decoded the stamp (s) and the six values (rad/s, m/s^2).
WalkRows = namedtuple('WalkRows', 'order stamp off length ok t data')


@jit(nogil=True)
def sqlite_walk(views, pages, layout, wanted, rows, slow,
                digest):  # pragma: no cover - compiled; tested against _batch
    """
    Walk table-leaf pages: rows of the wanted topics decoded, odd cells listed for Python.

    ``views``: the file's bytes ``u8`` and their little-endian uint32 / float64 views at every
    byte offset (:func:`byte_views`); ``pages``: page numbers; ``layout``: (page size, usable
    bytes per page); ``wanted``: topic ids.  Kept rows go to ``rows`` (:class:`WalkRows`);
    the cells that are not plain message rows on their page go to ``slow`` as (cell offset,
    page offset).
    Returns (rows kept, slow cells, pages that are not table leaves, table leaves whose
    free-space accounting fails (:func:`space_adds_up`, a cell before the content start or
    past the usable end included)), or (-1, 0, 0, 0) when an output array is too short or a
    page would make the numpy walk fail (the caller then runs that walk on the batch).
    ``digest[0]`` / ``digest[1]`` (uint64) add the plain rows of every topic: the sum of
    :func:`row_digest` and their count (once the batch is accepted: ``digest`` is changed
    only when the walk returns rows).
    """
    u8, u4, f8 = views
    page_size, usable = layout
    order, stamp, off, length, ok, t, data = rows
    last = u8.shape[0] - 1
    kept = 0
    nslow = 0
    lost = 0
    space = 0
    total = np.uint64(0)
    n_rows = 0
    for i in range(pages.shape[0]):
        base = (pages[i] - 1) * page_size
        hdr = base + 100 if pages[i] == 1 else base
        ncell = _get2(u8, hdr + 3)
        if u8[hdr] != 0x0D or 8 + 2 * ncell > page_size:
            lost += 1
            continue
        if hdr + 8 + 2 * ncell > base + page_size:
            return -1, 0, 0, 0   # page 1's pointers past its end: left to the numpy walk
        content = _get2(u8, hdr + 5)
        used = np.int64(0)
        fits = True
        for j in range(ncell):
            ptr = _get2(u8, hdr + 8 + 2 * j)
            cell = base + ptr
            # payload size, rowid, record header (size, four serial types), values
            p, n1 = _varint(u8, cell, last)
            rowid, n2 = _varint(u8, cell + n1, last)
            size = cell_size(p, n1, n2, usable)
            if size < 0 or ptr < (content if content else 65536) or ptr + size > usable:
                fits = False
            used += size
            rec = cell + n1 + n2
            hs, n3 = _varint(u8, rec, last)
            s0, a = _varint(u8, rec + n3, last)
            s1, b = _varint(u8, rec + n3 + a, last)
            s2, c = _varint(u8, rec + n3 + a + b, last)
            s3, d = _varint(u8, rec + n3 + a + b + c, last)
            z1 = _serial_size(s1)
            z2 = _serial_size(s2)
            v3 = rec + hs + z1 + z2
            blob = (s3 - 12) // 2
            if not (ptr >= 8 and ptr < page_size - 4 and hs == n3 + a + b + c + d
                    and s0 == 0 and z1 >= 0 and z2 >= 0 and s3 >= 12 and s3 % 2 == 0
                    and p >= 0 and p <= usable - 35 and v3 + blob <= base + page_size
                    and p == v3 + blob - rec):
                if nslow >= slow.shape[0]:
                    return -1, 0, 0, 0
                slow[nslow, 0] = cell
                slow[nslow, 1] = base
                nslow += 1
                continue
            topic = _be_int(u8, rec + hs, s1)
            received = _be_int(u8, rec + hs + z1, s2)
            total += row_digest(received, rowid)
            n_rows += 1
            hit = False
            for w in range(wanted.shape[0]):
                if topic == wanted[w]:
                    hit = True
            if not hit:
                continue
            if kept >= order.shape[0]:
                return -1, 0, 0, 0
            order[kept] = rowid
            stamp[kept] = received
            off[kept] = v3
            length[kept] = blob
            ok[kept] = decode_imu(u8, u4, f8, v3, blob, t, data, kept)
            kept += 1
        if not (fits and space_adds_up(u8, base, hdr, usable, used)):
            space += 1
    digest[0] += total
    digest[1] += np.uint64(n_rows)
    return kept, nslow, lost, space


@jit(nogil=True)
def sqlite_index_level(u8, pages, page_size, usable, digest,
                       children):  # pragma: no cover - compiled
    """
    Digest the entries of one level of a ``(timestamp)`` index B-tree; list the next level.

    As ``SqlitePages._index_batch`` (the numpy reference) on ``pages``: each entry's
    (timestamp, rowid) adds :func:`row_digest` to ``digest[0]`` and 1 to ``digest[1]``; the
    child pages of interior pages go to ``children``.  Returns the number of children, -1 for
    damage (a page that is no index page, a cell outside its page, a record that is not two
    integers, cells and free space that do not fill the page's content area as
    :func:`space_adds_up` checks) or -2 when ``children`` is too short.
    """
    last = u8.shape[0] - 1
    nchild = 0
    total = np.uint64(0)
    count = 0
    max_local = ((usable - 12) * 64 // 255) - 23   # larger payloads would overflow
    for i in range(pages.shape[0]):
        base = (pages[i] - 1) * page_size
        hdr = base + 100 if pages[i] == 1 else base
        kind = u8[hdr]
        if kind != 0x02 and kind != 0x0A:
            return -1
        interior = kind == 0x02
        head = 12 if interior else 8
        ncell = _get2(u8, hdr + 3)
        if hdr + head + 2 * ncell > base + page_size:
            return -1
        content = _get2(u8, hdr + 5)
        used = np.int64(0)
        for j in range(ncell):
            ptr = _get2(u8, hdr + head + 2 * j)
            if ptr < 8 or ptr > page_size - 8:
                return -1
            cell = base + ptr
            start = cell + 4 if interior else cell
            p, n1 = _varint(u8, start, last)
            rec = start + n1
            hs, n2 = _varint(u8, rec, last)
            s0, a = _varint(u8, rec + n2, last)
            s1, b = _varint(u8, rec + n2 + a, last)
            z0 = _serial_size(s0)
            z1 = _serial_size(s1)
            if (hs != n2 + a + b or z0 < 0 or z1 < 0 or p < hs
                    or rec + p > base + page_size):
                return -1
            size = max(rec + p - cell, np.int64(4))  # (left child,) payload size, payload
            if p > max_local or ptr < (content if content else 65536) or ptr + size > usable:
                return -1
            used += size
            total += row_digest(_be_int(u8, rec + hs, s0), _be_int(u8, rec + hs + z0, s1))
            count += 1
            if interior:
                if nchild >= children.shape[0]:
                    return -2
                children[nchild] = (_get2(u8, cell) << 16) | _get2(u8, cell + 2)
                nchild += 1
        if interior:
            if nchild >= children.shape[0]:
                return -2
            children[nchild] = (_get2(u8, hdr + 8) << 16) | _get2(u8, hdr + 10)
            nchild += 1
        if not space_adds_up(u8, base, hdr, usable, used):
            return -1
    digest[0] += total
    digest[1] += np.uint64(count)
    return nchild


#: Bytes of a Message record before its data, as ``mcap_scan.MESSAGE_HEADER`` (not imported
#: from there: that module loads this one).
MESSAGE_HEADER = 1 + 8 + 2 + 4 + 8 + 8

#: Largest MCAP log time (u64 on disk) that is a time: beyond it, the record is damaged.
_INT64_MAX = np.uint64((1 << 63) - 1)

#: What :func:`mcap_walk` does with a channel's messages (indexed by channel id).
LEAVE, COUNT, DECODE = 0, 1, 2


#: The views of ``u8`` :func:`mcap_walk` takes (:func:`byte_views`).
MCAP_VIEWS = ('<u2', '<u4', '<u8', '<f8')


@jit(nogil=True)
def mcap_walk(u8, u2, u4, u64, f8, pos, end, role, counts, log_time, off, length, ok, t,
              data):  # pragma: no cover - compiled; tested against the numpy walk
    """
    Walk the Message records of u8[pos:end] until one needs the scanner.

    ``u2`` / ``u4`` / ``u64`` / ``f8``: views of ``u8`` at every byte offset (:data:`MCAP_VIEWS`).
    ``role[channel id]``: :data:`DECODE` (kept rows go to ``log_time`` (ns), ``off`` /
    ``length`` (message data in ``u8``), ``ok`` and, where ok, ``t`` (s) and ``data``
    (rad/s, m/s^2)), :data:`COUNT` (only counted) or :data:`LEAVE`.  Every message walked is
    counted in ``counts[channel id]``.  Returns ``(pos, kept)``: the first record not walked
    (``end`` if none) and the rows kept; the walk also stops before a kept row that would not
    fit the output arrays or whose log time is beyond int64 (damage the scanner counts).
    """
    kept = 0
    room = t.shape[0]
    while end - pos >= 9 and u8[pos] == 0x05:
        size = np.int64(u64[pos + 1])
        if size < MESSAGE_HEADER - 9 or size > end - pos - 9:
            break
        cid = u2[pos + 9]
        what = role[cid]
        if what == LEAVE:
            break
        rec_end = pos + 9 + size
        if what == DECODE:
            if kept >= room or u64[pos + 15] > _INT64_MAX:
                break   # (a log time beyond int64 is damage: the scanner skips and counts it)
            log_time[kept] = np.int64(u64[pos + 15])
            start = pos + MESSAGE_HEADER
            off[kept] = start
            length[kept] = rec_end - start
            ok[kept] = decode_imu(u8, u4, f8, start, rec_end - start, t, data, kept)
            kept += 1
        counts[cid] += 1
        pos = rec_end
    return pos, kept


#: False where numba found no writable cache folder: compiling the walks (about 5 s) in every
#: process would cost more than they save, so :func:`.scan_common.compiled_walks` declines.
CACHED = not ({sqlite_walk.__name__, mcap_walk.__name__, sqlite_index_level.__name__}
              & set(UNCACHED))
