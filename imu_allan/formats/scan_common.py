"""
What the storage scanners share besides the codec and the collector.

Memory maps read front to back (:func:`map_file`, :class:`Passed`), the compiled walks' module
when it is worth loading (:func:`compiled_walks`), the chunk scanners' common part
(:class:`ChunkScan`, :class:`Runs`), the choice of the Imu topic and the one-line error text.
Used by :mod:`.mcap_scan`, :mod:`.sqlite_pages`, :mod:`.ros1_scan` and :mod:`.bag_reader`.
"""

from collections import defaultdict
import mmap
import struct
import sys

import numpy as np

from .imu_cdr import IMU_TYPE, IMU_TYPES
from ..errors import InputError


def compiled_walks(large):
    """
    Return the compiled walks' module (:mod:`.bag_kernels`, numba), or None.

    None (the numpy walk) for inputs too small to repay importing numba (``large`` False and
    numba not imported yet: about 1 s and 130-160 MB once per process), without numba, which
    is optional (same numbers, slower), and where the walk could not be cached (it would be
    compiled in every process).
    """
    if not large and 'numba' not in sys.modules:
        return None
    try:
        from . import bag_kernels
    except ImportError:
        return None
    return bag_kernels if bag_kernels.CACHED else None


def map_file(f):
    """Memory-map a whole file read-only."""
    return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)


def release(mm, start, stop):
    """
    Drop the pages of bytes [start, stop) of a read-only map from this process (not the file).

    The scanners read a map front to back: releasing what they have passed keeps the
    process's resident memory at the window in use instead of the whole file (which the
    kernel's page cache keeps anyway).  Harmless if touched again: the page comes back.
    """
    page = mmap.PAGESIZE
    lo = -(-int(start) // page) * page  # whole pages inside the range only
    hi = int(stop) // page * page
    if hi > lo:
        mm.madvise(mmap.MADV_DONTNEED, lo, hi - lo)


class Passed:
    """
    Release a read-only map's pages behind a scanner that walks it front to back.

    In steps of at least :attr:`STEP` bytes: each release is a system call that also makes
    every other thread of the process drop the pages (the chunk threads of the MCAP scan), so
    one per chunk of a few hundred kilobytes cost 0.08 s on a 10 h bag.
    """

    #: Bytes passed before they are released (resident memory grows by at most this much).
    STEP = 8 << 20

    def __init__(self, mm):
        """Nothing released yet."""
        self.mm, self.done = mm, 0

    def upto(self, end):
        """Release everything before byte ``end`` once it is STEP past the last release."""
        if end - self.done >= self.STEP:
            release(self.mm, self.done, end)
            self.done = int(end)


class Runs:
    """
    Runs of equal message records sliced out of a chunk with one numpy view (a scanner's walk).

    After a run shorter than 8 records the next 32 records are taken one by one: a view for
    every record of a file that mixes topics would cost more than it saves.
    """

    def __init__(self):
        """No run seen yet."""
        self.backoff = 0

    def take(self, u8, pos, end, stride, spans):
        """
        Return the records from ``pos`` equal to the first in the byte ``spans`` (k, stride).

        ``stride``: the first record's size; ``spans``: (start, stop) byte ranges that must
        match.  None when fewer than two records match or after a short run.
        """
        kmax = (end - pos) // stride
        if self.backoff or kmax < 2:
            self.backoff = max(self.backoff - 1, 0)
            return None
        block = u8[pos:pos + kmax * stride].reshape(kmax, stride)
        same = np.ones(kmax, dtype=bool)
        for a, b in spans:
            same &= (block[:, a:b] == block[0, a:b]).all(axis=1)
        k = kmax if same.all() else int(np.argmin(same))
        self.backoff = 0 if k >= 8 else 32
        return block[:k] if k > 1 else None


class ChunkScan:
    """What the MCAP and ROS 1 scanners share: what they collect and their chunk warnings."""

    def __init__(self, path, topic=None, collect=True, force_generic=False):
        """Scan ``path`` for ``topic`` (None: any Imu topic); only count unless ``collect``."""
        self.path = str(path)
        self.topic = topic
        self.collect = collect
        self.force_generic = force_generic
        self.counts = defaultdict(int)  # messages per channel (connection) id
        self.collectors = {}  # topic -> Collector
        self.warnings = []

    def _truncated(self, pos, end, where):
        self.warnings.append(f'{where} truncated at byte {pos} of {end}: rest skipped')

    def _walk_chunk(self, buf, start, stop, pos):
        """Walk the records buf[start:stop] of the chunk at byte ``pos`` of the file."""
        try:
            self._walk(buf[start:stop], 0, stop - start, top=False)
        except (struct.error, ValueError, IndexError, KeyError) as err:
            self.warnings.append(f'malformed record in the chunk at byte {pos} '
                                 f'({one_line(err)}): rest of that chunk skipped')

    def _walk_partial(self, buf, start, pos, end):
        """Read the complete records from ``start`` of a chunk at ``pos`` cut off at ``end``."""
        before = len(self.warnings)
        self._walk(buf[start:end], 0, end - start, top=False)
        del self.warnings[before:]
        self.warnings.append(f'file truncated at byte {end} inside the chunk starting at byte '
                             f'{pos}: its complete messages were read, the rest is lost')


def one_line(err):
    """Return an exception's text on one line of at most 200 characters."""
    text = ' '.join(str(err).split()) or type(err).__name__
    return text if len(text) < 200 else text[:197] + '...'


def choose_topic(path, topics, topic):
    """Pick the Imu topic to read from {topic: (type, count)} or raise InputError."""
    imu = [t for t, (typ, _) in topics.items() if typ in IMU_TYPES]
    if topic is not None:
        if topic not in topics:
            have = ', '.join(imu) if imu else 'none'
            raise InputError(path, f'no topic {topic} (Imu topics: {have})')
        if topics[topic][0] not in IMU_TYPES:
            raise InputError(path, f'topic {topic} is {topics[topic][0]}, not {IMU_TYPE}')
        return topic
    if not imu:
        raise InputError(path, f'no {IMU_TYPE} topic in the bag')
    if len(imu) > 1:
        raise InputError(path, f'several Imu topics ({", ".join(imu)}): choose one with --topic')
    return imu[0]
