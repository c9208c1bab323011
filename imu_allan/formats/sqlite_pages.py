"""
Direct reading of rosbag2 sqlite3 files by walking their SQLite pages.

File format: https://sqlite.org/fileformat.html.

The ``sqlite3`` module hands over one Python tuple per row, which caps near 700 k rows/s here;
a rosbag2 ``messages`` table is a plain rowid B-tree whose leaf cells are (NULL id alias,
topic_id, timestamp, data), so walking the tree and decoding the cells with numpy is faster,
and it also reads what is left of a truncated file (SQLite itself refuses such a file): the
rows of its intact pages.

The leaf pages are walked with numpy here (:meth:`SqlitePages._batch`, the reference) or, for
large files or once numba is loaded (:func:`compiled_walk`), by :func:`.bag_kernels.sqlite_walk`
(same result, about three times faster; numba is optional).
"""

import os
import struct
import threading

import numpy as np

from .imu_cdr import decode_at
from .scan_common import compiled_walks, map_file, release
from .sqlite_digest import row_digests
from ..errors import InputError

SQLITE_MAGIC = b'SQLite format 3\x00'
#: The columns of rosbag2's messages table, in the order the walks decode its rows.
MESSAGE_COLUMNS = ('id', 'topic_id', 'timestamp', 'data')

_SERIAL_SIZE = np.array([0, 1, 2, 3, 4, 6, 8, 8, 0, 0, -1, -1], dtype=np.int64)
#: Serial types that hold an integer (1-6 sized, 8 and 9 the constants 0 and 1), as a lookup
#: table (np.isin hashes its arguments on every call: a table lookup is several times faster).
_INTEGER_SERIAL = np.isin(np.arange(256), [1, 2, 3, 4, 5, 6, 8, 9])
#: Leaf pages of a table other than ``messages`` beyond which its rows are not checked
#: against its columns (a rosbag2 bag's small tables take a page or a few).
SMALL_TABLE_PAGES = 256
_PAGE_BATCH = 512  # leaf pages decoded per numpy batch (bounds the index arrays' memory)
_INDEX_CHUNK = 1024  # index pages copied (:meth:`SqlitePages._pages_copy`) and walked at a time


#: Leaf pages (about 12 Imu messages each at 4 KiB) from which the compiled walk reads a file
#: even when numba is not imported yet.  Importing numba and loading the walk costs about 1 s
#: and 130-160 MB (numba's runtime, whatever the file) once per process; from here on (0.6 M
#: messages) ``analyze`` loads numba anyway for the Allan deviation, so the cost moves earlier
#: instead of adding up, and the walk saves about 0.5 s per million messages.
COMPILED_MIN_PAGES = 50_000


def compiled_walk(npages):
    """Return the compiled walks' module (:mod:`.bag_kernels`) for ``npages``, or None."""
    return compiled_walks(npages >= COMPILED_MIN_PAGES)


class Unsupported(Exception):
    """The file uses a feature the direct readers do not handle: use the other path."""


def _be16(u8, pos):
    """Return the big-endian uint16 at byte(s) ``pos`` of ``u8`` (as int64)."""
    return u8[pos].astype(np.int64) * 256 + u8[pos + 1]


def _be32(u8, pos):
    """Return the big-endian uint32 at bytes ``pos`` of ``u8`` (as int64): page numbers."""
    return (_be16(u8, pos) << 16) | _be16(u8, pos + 2)


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
    """
    Parse 4-column record headers at ``rec``: (size, 4 serial types, consistent flag).

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
    # Clipped as in _varints: a damaged cell pointer near the end must not stop the walk.
    last = u8.shape[0] - 1
    same = (u8[np.minimum(rec[:, None] + span, last)]
            == u8[np.minimum(rec[0] + span, last)]).all(axis=1)
    out = [np.full(n, int(x[0]), dtype=np.int64) for x in first[:5]] + [np.ones(n, dtype=bool)]
    if not same.all():
        idx = np.nonzero(~same)[0]
        for dst, src in zip(out, parse(rec[idx])):
            dst[idx] = src
    return tuple(out)


class SqlitePages:
    """Minimal reader of a SQLite database file for rosbag2's tables."""

    def __init__(self, path):
        self.path = str(path)
        with open(self.path, 'rb') as f:
            self.size = f.seek(0, 2)
            f.seek(0)
            head = f.read(100)
            if len(head) < 100 or not head.startswith(SQLITE_MAGIC):
                raise InputError(self.path, 'not an SQLite database')
            self.mm = map_file(f)
        self.u8 = np.frombuffer(self.mm, dtype=np.uint8)
        self._views = None  # the compiled walk's unaligned views of u8 (made on first use)
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
        # (digest, count) of the message rows walked, every topic (:func:`row_digests`)
        self.digest = np.zeros(2, dtype=np.uint64)
        #: table-leaf pages walked whose free space does not add up (:meth:`space_failures`)
        #: or, in the small tables, with a record that does not fill its payload
        self.space_pages = 0
        self.indexes = {}  # index name -> (table name, root page), from sqlite_schema
        self.sql = []  # (kind, name, table, CREATE statement): sqlite_schema's tables, indexes
        self.schema_kinds = []  # the type column of every sqlite_schema row
        self.schema_roots = []  # (kind, root page) of its tables and indexes
        self.schema_roots_by_name = []  # (name, root page) of the same
        self._index = None  # the thread digesting the index, then its result

    def close(self):
        if isinstance(self._index, threading.Thread):
            self._index.join()
        self.u8 = self._views = None
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
        """
        Return the leaf page numbers of a table B-tree in key order (missing ones counted).

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
            if pages.size > 1 and u8[hdr[0]] == 0x0D:
                # B-trees are balanced: a level that starts with a leaf holds only leaves.
                # Their types are checked as each batch is read (:meth:`_batch`); checking them
                # here would bring the whole file into memory at once.
                return pages.tolist()
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
        ncell = int(_be16(u8, hdr + 3))
        right = struct.unpack_from('>I', self.mm, hdr + 8)[0]
        ptrs = self._ptrs(hdr, ncell, 4)
        if ptrs.size and (ptrs.max() + 4 > self.page_size or 12 + 2 * ncell > self.page_size):
            self.lost_pages += 1
            return np.zeros(0, dtype=np.int64)
        return np.append(_be32(u8, base + ptrs), right)

    def _payload(self, cell_off, page_base):
        """Full payload of one table-leaf cell (following overflow pages) and its rowid."""
        u8 = self.u8
        pos = np.array([cell_off])
        p, n1 = _varints(u8, pos)
        rowid, n2 = _varints(u8, pos + n1)
        p, start = int(p[0]), cell_off + int(n1[0]) + int(n2[0])
        if not 0 <= p < 1 << 31:  # a varint is 64 bits; SQLite's payloads stay below 2^31
            raise Unsupported('payload size out of range')
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
                raise Unsupported('overflow page missing')
            base = loc[0]
            nxt = struct.unpack_from('>I', self.mm, base)[0]
            take = min(p - len(out), usable - 4)
            out += self.mm[base + 4:base + 4 + take]
        return int(rowid[0]), bytes(out)

    @staticmethod
    def _record(payload, exact=False):
        """
        Decode a record (list of Python values) from its payload bytes.

        ``exact``: the record must fill the payload (Unsupported otherwise): a cell whose
        declared payload size differs from its record's is damaged (SQLite: overlapping
        cells).
        """
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
                raise Unsupported(f'serial type {st}')
        if exact and j != len(payload):
            raise Unsupported('record size differs from its payload size')
        return vals

    def table_rows(self, root):
        """
        All rows of a small table as (rowid, values) (Python, not for ``messages``).

        Its pages' free space and records are checked as the message table's
        (:meth:`space_failures`; a record that does not fill its payload): a failure counts
        in :attr:`space_pages`.
        """
        rows = []
        for no in self.leaf_pages(root):
            base, hdr = self._page(no)
            ncell = int(_be16(self.u8, hdr + 3))
            ptrs = self._ptrs(hdr, ncell, 0)
            p, n1 = _varints(self.u8, base + ptrs)
            n2 = _varints(self.u8, base + ptrs + n1)[1]
            bad = self.space_failures(self.u8, np.array([base]), np.array([hdr]),
                                      np.array([ncell]), ptrs, self.cell_sizes(p, n1, n2))
            for ptr in ptrs.tolist():
                rowid, payload = self._payload(base + ptr, base)
                try:
                    vals = self._record(payload, exact=True)
                except Unsupported:
                    bad, vals = 1, self._record(payload)
                if rows and rowid <= rows[-1][0]:
                    bad = 1  # rowids increase along a table (SQLite: "out of order")
                rows.append((rowid, vals))
            self.space_pages += bad
        return rows

    def schema(self):
        """Return {table name: root page} from sqlite_schema."""
        out = {}
        for _, vals in self.table_rows(1):
            if len(vals) >= 4 and vals[0] == 'table':
                out[vals[1]] = vals[3]
            elif len(vals) >= 4 and vals[0] == 'index' and isinstance(vals[3], int):
                self.indexes[vals[1]] = (vals[2], vals[3])
            self.schema_kinds.append(vals[0] if vals else None)
            if len(vals) >= 4 and vals[0] in ('table', 'index'):
                self.schema_roots.append((vals[0], vals[3]))
                self.schema_roots_by_name.append((str(vals[1]), vals[3]))
                self.sql.append((*vals[:3], vals[4] if len(vals) > 4 else None))
        return out

    def schema_problem(self):
        """
        Words when the schema's SQL is damaged or not the layout the walk assumes, else ''.

        SQLite parses the CREATE statements of sqlite_schema before any query and calls a
        file whose text it cannot parse malformed; here they are replayed into an empty
        in-memory database (SQLite's own parser, about a millisecond), then the messages
        table's columns are compared with the rosbag2 row the walk decodes.
        """
        import sqlite3
        odd = set(map(str, self.schema_kinds)) - {'table', 'index', 'view', 'trigger'}
        if odd:
            return f'a schema row of unknown type {sorted(odd)[0]:.20}'
        roots = [(typ, root) for typ, root in self.schema_roots if root]  # (views have 0)
        kinds = {'table': (0x0D, 0x05), 'index': (0x0A, 0x02)}
        for typ, root in roots:
            loc = self._page(root) if isinstance(root, int) and root > 1 else None  # 1: schema
            if loc is None or self.u8[loc[1]] not in kinds[typ]:
                return f'a {typ} of the schema has root page {root!s:.12}, no {typ} page'
        if len({root for _, root in roots}) != len(roots):
            return 'two tables or indexes of the schema share a root page'
        con = sqlite3.connect(':memory:')
        try:
            # Every object of the file's schema, its automatic indexes (a PRIMARY KEY or
            # UNIQUE that is no rowid alias) included, must come out of its statements.
            want = {(typ, str(name).lower(), str(table).lower())
                    for typ, name, table, _ in self.sql
                    if not str(name).startswith('sqlite_stat')}
            for kind in ('table', 'index'):  # (the tables first: an index names one)
                for typ, name, _, sql in self.sql:
                    if typ != kind or str(name).startswith('sqlite_'):
                        continue  # SQLite's own tables and automatic indexes
                    try:
                        con.execute(sql if isinstance(sql, str) else '')
                    except (sqlite3.Error, ValueError):
                        return f'the schema SQL of {name!s:.40} is damaged'
            made = {(typ, name.lower(), table.lower()) for typ, name, table in con.execute(
                "SELECT type, name, tbl_name FROM sqlite_master WHERE type IN ('table', "
                "'index')")}
            info = con.execute('PRAGMA table_info(messages)').fetchall()
            for typ, name, _, _ in self.sql:  # the small tables' rows fit their columns
                name = str(name)
                if typ == 'table' and name != 'messages' and not name.startswith('sqlite_'):
                    quoted = name.replace('"', '""')
                    ncol = len(con.execute(f'PRAGMA table_info("{quoted}")').fetchall())
                    if not self._rows_fit(dict(self.schema_roots_by_name).get(name), ncol):
                        return f'the rows of table {name:.40} do not fit its columns'
        finally:
            con.close()
        if made != want:  # the statements name other objects than their schema rows
            return 'the schema SQL names other tables or indexes than the schema rows'
        cols = [str(row[1]).lower() for row in info]
        if cols != list(MESSAGE_COLUMNS):
            return (f'the messages table\'s columns are ({", ".join(cols)[:80]}), not '
                    f'rosbag2\'s ({", ".join(MESSAGE_COLUMNS)})')
        if str(info[0][2]).upper() != 'INTEGER' or info[0][5] != 1:
            # only "id INTEGER PRIMARY KEY" makes id the rowid, stored as NULL in the rows
            return "the messages table's id is no INTEGER PRIMARY KEY in its schema SQL"
        return ''

    def _rows_fit(self, root, ncol):
        """Return True if the rows of a small table have ``ncol`` values (or it is too large)."""
        try:
            if len(self.leaf_pages(root)) > SMALL_TABLE_PAGES:
                return True
            return all(len(vals) == ncol for _, vals in self.table_rows(root))
        except (Unsupported, IndexError, struct.error, ValueError, TypeError):
            return False

    def structure_problem(self):
        """
        Words on damage that SQLite would see beside the rows' own checks, or ''.

        Call after :meth:`read_messages`: the free-space accounting of the pages walked
        (:meth:`space_failures`), then the schema's SQL (:meth:`schema_problem`).
        """
        schema = self.schema_problem()  # (reads the small tables: their pages count too)
        if self.space_pages:
            return (f'the cells and free space of {self.space_pages} table page(s) do not '
                    'add up')
        return schema

    def topics(self, root):
        """Return [(topic id, name, type)] from rosbag2's topics table."""
        out = []
        for rowid, vals in self.table_rows(root):
            tid = rowid if vals[0] is None else vals[0]
            out.append((tid, vals[1], vals[2]))
        return out

    def index_digest(self, root):
        """
        Return (digest, entries) of a ``(timestamp)`` index B-tree, or None if it is damaged.

        Every page of the tree is visited level by level (interior index pages hold entries
        too); each entry is a record (timestamp, rowid), digested as the table's rows are
        (:func:`row_digests`).  Any page that is not an index page, a cell pointer outside its
        page, a record that is not two integers, cells and free space that do not fill the
        page's content area (:meth:`space_failures`: SQLite's "Multiple uses for byte" and
        "Fragmentation" lines), or more pages than the file holds (a loop) is damage: None.
        """
        u8, ps = self.u8, self.page_size
        level = np.array([root], dtype=np.int64)
        total, count, seen = np.zeros(1, dtype=np.uint64), 0, 0  # (an array adds wrapping)
        kernel = compiled_walk(self.npages)
        while level.size:
            seen += level.size
            if seen > self.npages or ((level < 1) | (level > self.npages)).any():
                return None
            if kernel is not None:  # the compiled walk of the level (same digest, ~10x faster)
                nxt = []
                for c0 in range(0, level.size, _INDEX_CHUNK):
                    buf, local = self._pages_copy(level[c0:c0 + _INDEX_CHUNK])
                    hdr = (local - 1) * ps
                    inner = buf[hdr] == 0x02
                    room = int((_be16(buf, hdr[inner] + 3) + 1).sum())
                    digest = np.zeros(2, dtype=np.uint64)
                    children = np.empty(room, dtype=np.int64)
                    n = kernel.sqlite_index_level(buf, local, ps, self.usable, digest,
                                                  children)
                    if n < 0:
                        return None
                    total += digest[:1]
                    count += int(digest[1])
                    nxt.append(children[:n])
                level = np.concatenate(nxt)
                continue
            nxt = []
            for b0 in range(0, level.size, _PAGE_BATCH):
                pages = level[b0:b0 + _PAGE_BATCH]
                got = self._index_batch(u8, ps, pages)
                if got is None:
                    return None
                digest, n, children = got
                total += np.array([digest], dtype=np.uint64)
                count += n
                nxt.append(children)
            level = np.concatenate(nxt)
        return total[0], count

    def _pages_copy(self, pages):
        """
        Read ``pages`` (numbers) into a private buffer; return it and their numbers in it.

        The index walk reads its pages with ``pread``, not through the map: its pages lie
        scattered between the table's, and each fault on the map brings the neighbouring
        pages (already cached by the table walk) into this process as well (the kernel's
        fault-around), which took the 10 h bag's peak resident memory from 0.4 GB to 1.25 GB.
        Page k of ``pages`` sits at page k + 2 of the buffer (page 1, whose B-tree header
        starts at byte 100, is left empty: a copy of it is no index page either way).
        """
        ps = self.page_size
        fd = os.open(self.path, os.O_RDONLY)
        try:
            parts = [bytes(ps)] + [os.pread(fd, ps, (no - 1) * ps) for no in pages.tolist()]
        finally:
            os.close(fd)
        if any(len(part) != ps for part in parts):
            raise ValueError('index page beyond the end of the file')  # (cut meanwhile)
        return (np.frombuffer(b''.join(parts), dtype=np.uint8),
                np.arange(2, pages.size + 2, dtype=np.int64))

    def _index_batch(self, u8, ps, pages):
        """Digest, entry count and child pages of a batch of index pages (None if damaged)."""
        base = (pages - 1) * ps
        hdr = base + np.where(pages == 1, 100, 0)
        kind = u8[hdr]
        interior = kind == 0x02
        if not (interior | (kind == 0x0A)).all():
            return None
        ncell = _be16(u8, hdr + 3)
        head = np.where(interior, 12, 8)
        if (hdr + head + 2 * ncell > base + ps).any():
            return None
        j = np.arange(int(ncell.max()) if ncell.size else 0)
        mask = j[None, :] < ncell[:, None]
        pp = (hdr + head)[:, None] + 2 * j[None, :]
        pp = pp[mask]
        ptr = _be16(u8, pp)
        cbase = np.repeat(base, ncell)
        inner = np.repeat(interior, ncell)
        if ((ptr < 8) | (ptr > ps - 8)).any():
            return None
        cell = cbase + ptr
        start = cell + np.where(inner, 4, 0)  # an interior cell starts with its left child
        p, n1 = _varints(u8, start)
        rec = start + n1
        hs, n2 = _varints(u8, rec)
        s0, a = _varints(u8, rec + n2)
        s1, b = _varints(u8, rec + n2 + a)
        ok = ((hs == n2 + a + b) & _INTEGER_SERIAL[np.clip(s0, 0, 255)] & (s0 < 10)
              & _INTEGER_SERIAL[np.clip(s1, 0, 255)] & (s1 < 10) & (p >= hs)
              & (rec + p <= cbase + ps))
        if not ok.all():
            return None
        # (left child,) payload size and payload: the cells must fill the content area
        usable = self.usable
        size = np.where(p > ((usable - 12) * 64 // 255) - 23, -1, np.maximum(rec + p - cell, 4))
        if self.space_failures(u8, base, hdr, ncell, ptr, size):
            return None
        ts = _be_ints(u8, rec + hs, s0)
        rowid = _be_ints(u8, rec + hs + _SERIAL_SIZE[s0], s1)
        digest = row_digests(ts, rowid)
        left, right = _be32(u8, cell[inner]), _be32(u8, hdr[interior] + 8)
        return digest, int(ptr.size), np.concatenate([left, right])

    def _index_roots(self, table='messages'):
        return [root for _, (tbl, root) in sorted(self.indexes.items()) if tbl == table]

    def _digest_index(self, root):
        try:
            got = self.index_digest(root)
            self._index = 'damaged' if got is None else got
        except Exception:  # noqa: B902 - a thread must not die with damage: say "damaged"
            self._index = 'damaged'

    def index_problem(self, table='messages'):
        """
        Compare the rows walked with the table's timestamp index; words on a mismatch, or ''.

        Only for an intact walk of the whole table (:meth:`read_messages` on a file not found
        damaged) with one index of (timestamp): SQLite keeps one entry per row there, so a row
        whose timestamp or rowid changed, a lost row or a cell read twice (overlapping cells)
        shows as a different digest or count.
        """
        roots = self._index_roots(table)
        if len(roots) != 1:
            return ''
        if isinstance(self._index, threading.Thread):
            self._index.join()
        if self._index is None:
            self._digest_index(roots[0])
        got = self._index if isinstance(self._index, tuple) else None
        rows = int(self.digest[1])
        if got is None:
            return 'its timestamp index is damaged'
        if got[1] != rows:
            return f'{rows} rows in the message table, {got[1]} in its timestamp index'
        if got[0] != self.digest[0]:
            return ('rows of the message table differ from its timestamp index (a damaged '
                    'timestamp or row id)')
        return ''

    @property
    def damaged(self):
        """Return True if the file is shorter than its header says or the tree lost pages."""
        return bool(self.declared > self.npages or self.size % self.page_size or self.lost_pages)

    def read_messages(self, root, topic_ids, coll):
        """
        Feed the messages of ``topic_ids`` to a collector, in numpy batches.

        An intact file is read along the B-tree; a damaged one by trying every table-leaf
        page (a cut file can lose the interior pages that lead to intact leaves). Only cells
        shaped like rosbag2 message rows are taken; the rowid orders them.
        """
        leaves = np.asarray(self.leaf_pages(root), dtype=np.int64)
        if self.damaged:
            every = np.arange(1, self.npages + 1, dtype=np.int64)
            hdr = (every - 1) * self.page_size + np.where(every == 1, 100, 0)
            leaves = every[self.u8[hdr] == 0x0D]
            release(self.mm, 0, self.size)  # one byte of every page read: let them go
        wanted = np.asarray(sorted(topic_ids), dtype=np.int64)
        kernel = None if coll.force_generic or coll.ros1 else compiled_walk(leaves.shape[0])
        roots = self._index_roots()
        if kernel is not None and len(roots) == 1 and not self.damaged:
            # The index's digest on the other core meanwhile (the compiled walk drops the GIL)
            self._index = threading.Thread(target=self._digest_index, args=(roots[0],),
                                           daemon=True)
            self._index.start()
        for b0 in range(0, leaves.shape[0], _PAGE_BATCH):
            pages = leaves[b0:b0 + _PAGE_BATCH]
            if kernel is None or not self._walk(kernel, pages, wanted, coll):
                self._batch(pages, wanted, coll)
            release(self.mm, (pages.min() - 1) * self.page_size, pages.max() * self.page_size)

    def _walk(self, kernel, pages, wanted, coll):
        """
        Read a batch of leaf pages with the compiled walk; False if it left them to _batch.

        Same outcome as :meth:`_batch` (the tests compare them), in one pass per page:
        the rows of one batch form one part, in cell order.
        """
        u8, ps = self.u8, self.page_size
        hdr = (pages - 1) * ps + np.where(pages == 1, 100, 0)
        ncell = _be16(u8, hdr + 3)
        cells = int(ncell[(u8[hdr] == 0x0D) & (8 + 2 * ncell <= ps)].sum())  # pages it walks
        order, stamp, off, length = np.empty((4, cells), dtype=np.int64)
        ok = np.empty(cells, dtype=bool)
        slots = coll.reserved(cells)
        t, data = slots if slots is not None else (np.empty(cells), np.empty((cells, 6)))
        slow = np.empty((cells, 2), dtype=np.int64)
        if self._views is None:
            self._views = kernel.byte_views(u8)
        kept, nslow, lost, space = kernel.sqlite_walk(
            (u8, *self._views), pages, (ps, self.usable), wanted,
            kernel.WalkRows(order, stamp, off, length, ok, t, data), slow, self.digest)
        if kept < 0:
            return False
        self.lost_pages += lost
        self.space_pages += space
        t, data = t[:kept], data[:kept]
        if nslow:  # the slow cells' parts go first (as in _batch) into the reserved places
            t, data = t.copy(), data.copy()
            for cell, page_base in slow[:nslow].tolist():
                self._slow_cell(cell, page_base, wanted, coll)
        if kept == 0:
            return True
        off, length = off[:kept], length[:kept]

        def blob_of(i):
            return bytes(self.mm[int(off[i]):int(off[i] + length[i])])
        coll.add_decoded(stamp[:kept].copy(), t, data, ok[:kept], blob_of,
                         order=order[:kept].copy())
        return True

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
        ncell = _be16(u8, hdr + 3)
        good_page = (u8[hdr] == 0x0D) & (8 + 2 * ncell <= ps)
        if not good_page.all():
            self.lost_pages += int((~good_page).sum())
            base, hdr, ncell = base[good_page], hdr[good_page], ncell[good_page]
        maxc = int(ncell.max()) if ncell.size else 0
        j = np.arange(maxc)
        mask = j[None, :] < ncell[:, None]
        pp = (hdr[:, None] + 8 + 2 * j[None, :])[mask]
        ptr = _be16(u8, pp)
        cbase = np.repeat(base, ncell)
        cell = cbase + ptr
        inside = (ptr >= 8) & (ptr < ps - 4)
        # Cell layout: payload size, rowid, record header (size, 4 serial types), values.
        p, n1 = _varints(u8, cell)
        rowid, n2 = _varints(u8, cell + n1)
        self.space_pages += self.space_failures(u8, base, hdr, ncell, ptr,
                                                self.cell_sizes(p, n1, n2))
        if ncell.sum() == 0:
            return
        rec = cell + n1 + n2
        hs, s0, s1, s2, s3, fits = _record_headers(u8, rec)
        fast = (inside & fits & (s0 == 0) & _INTEGER_SERIAL[np.clip(s1, 0, 255)]
                & _INTEGER_SERIAL[np.clip(s2, 0, 255)] & (s3 >= 12) & (s3 % 2 == 0)
                & (p >= 0) & (p <= self.usable - 35))  # a 9-byte varint can wrap negative
        v1 = rec + hs
        v2 = v1 + _SERIAL_SIZE[np.where(fast, s1, 0)]
        v3 = v2 + _SERIAL_SIZE[np.where(fast, s2, 0)]
        blob_len = (s3 - 12) // 2
        # ... and the record (header and values) is exactly the payload the cell declares
        fast &= (v3 + blob_len <= cbase + ps) & (p == v3 + blob_len - rec)
        order = rowid  # ties in receive time keep rowid order, as ORDER BY timestamp, id
        if not fast.all():
            for i in np.nonzero(~fast)[0].tolist():
                self._slow_cell(int(cell[i]) + shift, int(cbase[i]) + shift, wanted, coll)
        topic = _be_ints(u8, v1, np.where(fast, s1, 8))
        received = _be_ints(u8, v2, np.where(fast, s2, 8))  # every topic's, for the digest
        self.digest += np.array([row_digests(received[fast], rowid[fast]),
                                 np.count_nonzero(fast)], dtype=np.uint64)
        keep = fast & (topic == wanted[0] if wanted.size == 1 else np.isin(topic, wanted))
        if not keep.any():
            return
        stamp = received[keep]
        off, length, order = v3[keep], blob_len[keep], order[keep]
        for ln in (length[:1] if length.min() == length.max() else np.unique(length)):
            sel = length == ln
            ok, t, data = decode_at(u8, off[sel], int(ln), ros1=coll.ros1)
            if coll.force_generic:
                ok[:] = False

            def blob_of(i, at=off[sel] + shift, ln=int(ln)):
                return bytes(self.mm[int(at[i]):int(at[i]) + ln])
            for i in np.nonzero(~ok)[0].tolist():
                t[i], data[i] = coll.generic(blob_of(i))
            coll.add_part(order[sel], stamp[sel], t, data, blob_of)

    def cell_sizes(self, p, n1, n2):
        """
        Bytes each table-leaf cell takes on its page (-1: payload size out of range).

        SQLite's ``cellSizePtr``: the varints of payload size (``n1`` bytes) and rowid
        (``n2``), the payload's local part (all ``p`` bytes up to ``usable - 35``, else the
        share kept on the page by the file format's overflow rule) and a 4-byte overflow page
        number; at least 4 bytes.  (:func:`.bag_kernels.cell_size` for one cell.)
        """
        usable = self.usable
        x = usable - 35
        m = ((usable - 12) * 32 // 255) - 23
        ok = (p >= 0) & (p < 1 << 31)
        q = np.where(ok, p, 0)
        k = m + (q - m) % (usable - 4)
        local = np.where(q <= x, q, np.where(k <= x, k, m) + 4)
        return np.where(ok, np.maximum(n1 + n2 + local, 4), -1)

    def space_failures(self, u8, base, hdr, ncell, ptr, size):
        """
        Count the table-leaf pages whose free-space accounting fails.

        The cell content area (from the header's content start to the usable end) must be
        exactly the cells, the freeblocks (a chain of increasing offsets inside the area) and
        the fragmented bytes the header counts: SQLite's integrity_check ("Fragmentation of
        ... reported as ...").  A cell before the content start or past the usable end, or of
        a payload size out of range (``size`` -1), fails its page.  ``base`` / ``hdr``: the
        pages' offsets in ``u8``; ``ptr`` / ``size``: their cells, page by page.
        (:func:`.bag_kernels.space_adds_up` in the compiled walk.)
        """
        if not ncell.size:
            return 0
        usable = self.usable
        content = _be16(u8, hdr + 5)
        content = np.where(content == 0, 65536, content)
        page = np.repeat(np.arange(ncell.size), ncell)
        stray = (size < 0) | (ptr < content[page]) | (ptr + size > usable)
        used = np.zeros(ncell.size, dtype=np.int64)
        np.add.at(used, page, size)
        bad = np.zeros(ncell.size, dtype=bool)
        bad[page[stray]] = True
        first = _be16(u8, hdr + 1)
        free = np.zeros(ncell.size, dtype=np.int64)
        for i in np.flatnonzero(first).tolist():  # freeblocks: rare in a bag (no deletes)
            fb, b0 = int(first[i]), int(base[i])
            while fb:
                if fb < content[i] or fb + 4 > usable:
                    bad[i] = True
                    break
                nxt = int(_be16(u8, b0 + fb))
                free[i] += int(_be16(u8, b0 + fb + 2))
                if nxt and nxt <= fb:
                    bad[i] = True
                    break
                fb = nxt
        bad |= usable - content != used + free + u8[hdr + 7]
        return int(bad.sum())

    def _slow_cell(self, cell, page_base, wanted, coll):
        if not page_base <= cell < page_base + self.page_size - 4:
            self.lost_pages += 1
            return
        try:
            order, payload = self._payload(cell, page_base)
            vals = self._record(payload, exact=True)
        except (Unsupported, IndexError, struct.error):
            self.lost_pages += 1
            return
        if len(vals) == 4 and isinstance(vals[2], int):  # a row of any topic: the digest
            self.digest += np.array([row_digests([vals[2]], [order]), 1], dtype=np.uint64)
        if len(vals) == 4 and vals[1] in wanted.tolist() and isinstance(vals[3], bytes):
            if not isinstance(vals[2], int):  # a receive time that is no integer: damage
                self.lost_pages += 1
                return
            stamp, blob = vals[2], vals[3]
            t, row = coll.generic(blob)
            coll.add_part(np.array([order]), np.array([stamp]), np.array([t]),
                          row.reshape(1, 6), lambda _: blob)
