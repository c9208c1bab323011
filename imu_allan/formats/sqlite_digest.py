"""
The digest that checks a rosbag2 ``messages`` table against its ``(timestamp)`` index.

Both walks of a sqlite3 bag sum it: the numpy one (:mod:`.sqlite_pages`, :func:`row_digests`)
and the compiled one (:func:`.bag_kernels.row_digest`, which reads the multipliers from here).
A module of its own, without numba, so that the compiled walks do not import the page reader
that loads them.
"""

import numpy as np

#: Multipliers of the row digest (:func:`row_digests`): odd 64-bit constants (the golden
#: ratio's and a MurmurHash3 finaliser's) that spread the bits of timestamp and rowid.  Also
#: used by the compiled walk (:mod:`.bag_kernels`): never change them (numba's disk cache
#: checks only that walk's own file, and would keep the old ones).
DIGEST_TS = np.uint64(0x9E3779B97F4A7C15)
DIGEST_ROWID = np.uint64(0xC2B2AE3D27D4EB4F)


def row_digests(stamp, rowid):
    """
    Return the digest of rows (timestamp, rowid): the wrapping sum of their mixed bits.

    Independent of the order of the rows, so the table's rows (walked in rowid order) and the
    entries of its ``(timestamp)`` index (walked level by level) give the same digest exactly
    when they hold the same pairs (up to a collision, about 2^-64 per damaged pair).
    """
    ts = np.asarray(stamp, dtype=np.int64).view(np.uint64)
    rid = np.asarray(rowid, dtype=np.int64).view(np.uint64)
    return np.bitwise_xor(ts * DIGEST_TS, rid * DIGEST_ROWID).sum(dtype=np.uint64)
