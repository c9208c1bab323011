"""
The scanners' accumulator: serialized Imu messages of one topic, in file order, decoded in bulk.

Every storage scanner (:mod:`.mcap_scan`, :mod:`.sqlite_pages`, :mod:`.ros1_scan`) and
:mod:`.bag_reader` hand their messages to a :class:`Collector`, which decodes them with the
codec (:mod:`.imu_cdr`), drops and counts the damaged ones and words the warnings about them
(one wording for every reader).
"""

import numpy as np

from .imu_adapter import imu_to_row
from .imu_cdr import decode_rows, frame_id_of, valid_stamp


def damaged_warning(count):
    """Return the reader's warning about ``count`` dropped messages (one wording for all)."""
    return (f'{count} damaged message(s) could not be decoded (bad layout or a nanosecond '
            'field of 1e9 or more) and were skipped')


#: Largest receive time (ns) a reader keeps: the int64 the storages define it as (MCAP's u64
#: log_time beyond it is no time a recorder writes, and it would not fit the arrays).
INT64_MAX = (1 << 63) - 1


def bad_time_warning(count):
    """Return the reader's warning about ``count`` records with an out-of-range receive time."""
    return (f'{count} damaged message record(s) with a receive time out of range (beyond '
            'int64 ns, or a nanosecond field of 1e9 or more) were skipped')


class Collector:
    """Accumulate serialized Imu messages of one connection in file order, decode in bulk."""

    def __init__(self, ros1, deserialize, force_generic=False, capacity=0):
        """
        Collect one topic; ``capacity`` bounds the messages to expect (0: unknown).

        With a capacity (the scanners pass their file's size over the smallest Imu message),
        decoded values go straight into arrays of that length, reserved but not touched (the
        operating system gives pages on first write), and :meth:`result` returns views of
        them: no concatenation, so reading holds one copy of the samples instead of two.
        """
        self.ros1 = ros1
        self.deserialize = deserialize
        self.force_generic = force_generic  # reference path: every message deserialized
        # (order, log_time, t, data) arrays; order is a range for consecutive numbers (most
        # parts): at 10 h the numbers would take 29 MB, kept until the end and then left to
        # the allocator as scattered free blocks
        self.parts = []
        self.single_order = []
        self.single_time = []
        self.single_blob = []
        self.count = 0
        self.undecodable = 0  # messages the deserializer rejected (dropped, with a warning)
        self.bad_times = 0  # records whose receive time is out of range (skipped, counted)
        self._first = None  # (log_time, order, bytes) of the earliest message seen
        self._fill = 0
        self._t = np.empty(int(capacity)) if capacity else None
        self._data = np.empty((int(capacity), 6)) if capacity else None

    def add_part(self, order, log_time, t, data, raw):
        """
        Add decoded messages: file order numbers, receive times (ns), stamps (s), values.

        ``raw(i)`` returns the bytes of message i; only the earliest message's are kept, for
        :attr:`frame_id`.
        """
        k = len(order)
        if self._t is not None and self._fill + k <= self._t.shape[0]:
            a, self._fill = self._fill, self._fill + k
            if not (k and _same_place(t, self._t[a:]) and _same_place(data, self._data[a:])):
                self._t[a:self._fill] = t
                self._data[a:self._fill] = data
            t, data = self._t[a:self._fill], self._data[a:self._fill]
        else:
            self._t = self._data = None  # capacity exceeded: concatenate parts in result()
        self.parts.append((order, log_time, t, data))
        self.undecodable += int(np.count_nonzero(np.isnan(t)))
        if len(order):
            i = int(np.argmin(log_time))  # the first of equal times: lowest order in a part
            key = (int(log_time[i]), int(order[i]))
            if self._first is None or key < self._first[:2]:
                self._first = (*key, raw(i))

    def prefault(self):
        """Write zeros into the reserved arrays, so that filling them later finds their pages."""
        if self._t is not None:
            self._t[self._fill:] = 0.0
            self._data[self._fill:] = 0.0

    def reserved(self, k):
        """
        Return views (t, data) of the next ``k`` reserved places, or None if fewer remain.

        A decoder may write there and pass (a prefix of) the views to :meth:`add_part`, which
        then copies nothing; anything added before that overwrites them.
        """
        if self._t is None or self._fill + k > self._t.shape[0]:
            return None
        return self._t[self._fill:self._fill + k], self._data[self._fill:self._fill + k]

    @property
    def frame_id(self):
        """Return the ``header.frame_id`` of the earliest message ('' if none was added)."""
        return '' if self._first is None else frame_id_of(self._first[2], self.ros1)

    def _decode(self, rows, blob_of):
        """Bulk-decode equal-length rows; the generic deserializer takes what bulk cannot."""
        ok, t, data = decode_rows(rows, self.ros1)
        if self.force_generic:
            ok[:] = False
        for i in np.nonzero(~ok)[0]:
            t[i], data[i] = self.generic(blob_of(i))
        return t, data

    def add_decoded(self, log_time, t, data, ok, blob_of, order=None):
        """
        Add k messages a compiled walk decoded where ``ok``; generic deserializing for the rest.

        ``log_time``: receive times (ns); ``t`` / ``data``: their stamps (s) and values, written
        here where not ``ok``; ``blob_of(i)``: the bytes of message i; ``order``: their file
        order numbers (default: the next k).
        """
        if order is None:
            order = range(self.count, self.count + len(t))
            self.count += len(t)
        for i in np.flatnonzero(~ok).tolist():
            t[i], data[i] = self.generic(blob_of(i))
        self.add_part(order, log_time, t, data, blob_of)

    def add_rows(self, log_time, rows, bad=None):
        """
        Add k messages given as a (k, L) uint8 array with their receive times (ns).

        ``log_time`` may be uint64 (MCAP): values beyond int64 are damaged records, skipped
        and counted (:attr:`bad_times`), as are the rows where ``bad`` (the caller's range
        check) is True.
        """
        if log_time.dtype == np.uint64:
            over = log_time > np.uint64(INT64_MAX)
            bad = over if bad is None else bad | over
        if bad is not None and bad.any():
            self.bad_times += int(np.count_nonzero(bad))
            rows, log_time = rows[~bad], log_time[~bad]
        k = rows.shape[0]
        order = range(self.count, self.count + k)
        self.count += k

        def blob_of(i):
            return rows[i].tobytes()
        t, data = self._decode(rows, blob_of)
        self.add_part(order, log_time.astype(np.int64), t, data, blob_of)

    def add_blobs(self, log_times, blobs):
        """
        Add messages given as bytes with their receive times (ns).

        A receive time that is no int64 (out of range, or not an integer: a damaged sqlite3
        row) makes its message a damaged record, skipped and counted.
        """
        try:
            log_times = np.asarray(log_times, dtype=np.int64)
        except (OverflowError, TypeError, ValueError):  # the rare damaged file: one by one
            good = [i for i, x in enumerate(log_times)
                    if isinstance(x, int) and -INT64_MAX - 1 <= x <= INT64_MAX]
            self.bad_times += len(log_times) - len(good)
            log_times = np.array([log_times[i] for i in good], dtype=np.int64)
            blobs = [blobs[i] for i in good]
        order = np.arange(self.count, self.count + len(blobs))
        self.count += len(blobs)
        self._add_grouped(order, log_times, blobs)

    def _add_grouped(self, order, log_times, blobs):
        """Decode messages (bytes) grouped by length, keeping their order numbers."""
        if not blobs:
            return
        lens = np.fromiter(map(len, blobs), dtype=np.int64, count=len(blobs))
        order = np.asarray(order, dtype=np.int64)
        times = np.asarray(log_times, dtype=np.int64)
        for length in np.unique(lens):
            idx = np.nonzero(lens == length)[0]
            joined = (b''.join(blobs) if idx.size == len(blobs)
                      else b''.join([blobs[i] for i in idx]))
            rows = np.frombuffer(joined, dtype=np.uint8).reshape(idx.size, int(length))

            def blob_of(j, idx=idx):
                return blobs[idx[j]]
            t, data = self._decode(rows, blob_of)
            self.add_part(order[idx], times[idx], t, data, blob_of)

    def add_one(self, log_time, blob):
        """
        Add one message (bytes) with its receive time (ns); decoded in bulk later.

        A receive time beyond int64 (a damaged u64 field) or None (the caller's range check
        failed) skips the record, counted in :attr:`bad_times`.
        """
        if log_time is None or not -INT64_MAX - 1 <= log_time <= INT64_MAX:
            self.bad_times += 1
            return
        self.single_order.append(self.count)
        self.single_time.append(log_time)
        self.single_blob.append(blob)
        self.count += 1

    def generic(self, blob):
        """Deserialize one message; NaN stamp (dropped and counted) if it is garbage."""
        try:
            msg = self.deserialize(blob)
            t, row = imu_to_row(msg)
        except Exception:  # any deserializer failure means this one message is unusable
            return np.nan, np.full(6, np.nan)
        return (t if valid_stamp(msg) else np.nan), row

    def warnings(self):
        """Warning lines about this collector's messages."""
        out = [damaged_warning(self.undecodable)] if self.undecodable else []
        return out + ([bad_time_warning(self.bad_times)] if self.bad_times else [])

    def _flush_singles(self):
        order, times, blobs = self.single_order, self.single_time, self.single_blob
        self.single_order, self.single_time, self.single_blob = [], [], []
        self._add_grouped(order, times, blobs)

    def result(self):
        """Return (t, data) sorted by receive time, ties in file order (as rosbags yields)."""
        self._flush_singles()
        if not self.parts:
            return np.zeros(0), np.zeros((0, 6))
        if self._t is not None:  # every part went into the reserved arrays, in turn
            t, data = self._t[:self._fill], self._data[:self._fill]
        else:
            t = np.concatenate([p[2] for p in self.parts])
            data = np.concatenate([p[3] for p in self.parts])
        if not self._in_order():
            order = np.concatenate([np.asarray(p[0], dtype=np.int64) for p in self.parts])
            log_time = np.concatenate([p[1] for p in self.parts])
            idx = np.lexsort((order, log_time))
            t, data = t[idx], data[idx]
        return self._drop_undecodable(t, data)

    def _in_order(self):
        """Return True if the parts are already in (receive time, file order) order (usual)."""
        last = None
        for order, log_time, *_ in self.parts:
            if len(order) == 0:
                continue
            rising = isinstance(order, range) or np.all(order[1:] > order[:-1])
            if not (rising and np.all(log_time[1:] >= log_time[:-1])):
                return False
            if last is not None and not (order[0] > last[0] and log_time[0] >= last[1]):
                return False
            last = order[-1], log_time[-1]
        return True

    def _drop_undecodable(self, t, data):
        if not self.undecodable:
            return t, data
        keep = ~np.isnan(t)
        return t[keep], data[keep]


def _same_place(a, b):
    """Return True if arrays ``a`` and ``b`` start at the same address with the same strides."""
    return (a.__array_interface__['data'][0] == b.__array_interface__['data'][0]
            and a.strides == b.strides)
