"""
The batch oracle for the online estimator with gaps: segments, and the batch estimator pooled.

Shared by test_streaming.py and test_hostile_online.py.
"""

from imu_allan.core.allan.estimate import allan_deviation
import numpy as np


def split_segments(column, left_out, brk=None):
    """Segments of ``column`` (1-D): runs between left-out samples, also cut before ``brk``."""
    brk = np.zeros(column.size, bool) if brk is None else brk
    segments, start = [], 0
    for i in range(column.size + 1):
        if i == column.size or left_out[i] or brk[i]:
            if i > start:
                segments.append(column[start:i])
            start = i + 1 if i < column.size and left_out[i] else i
    return segments


def pooled_batch(segments, ms, rate_hz):
    """
    Apply the batch estimator to each segment (1-D) and pool: ``(avar (F,), count (F,))``.

    Pooling weighs each segment's AVAR by its number of terms K = L - 2m + 1 (L samples);
    NaN where no segment is long enough for a factor.
    """
    ms = np.asarray(ms)
    total, count = np.zeros(ms.size), np.zeros(ms.size, np.int64)
    for seg in segments:
        fits = np.flatnonzero(2 * ms <= seg.size)
        if not fits.size:
            continue
        res = allan_deviation(seg, rate_hz, taus=ms[fits] / rate_hz)
        np.testing.assert_array_equal(res.m, ms[fits])
        k = seg.size - 2 * res.m + 1
        total[fits] += res.avar[:, 0] * 2.0 * res.m * res.m * k
        count[fits] += k
    with np.errstate(invalid='ignore'):
        return total / (2.0 * ms.astype(float) ** 2 * count), count


def feed_chunked(est, data, seed, use=None, brk=None):
    """Feed ``data`` (and its masks) to a streaming estimator in seeded random chunks."""
    rng = np.random.default_rng(seed)
    i = 0
    while i < data.shape[0]:
        n = int(rng.integers(1, 3000))
        est.update(data[i:i + n], None if use is None else use[i:i + n],
                   None if brk is None else brk[i:i + n])
        i += n
