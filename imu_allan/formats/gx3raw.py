"""
Read a raw 3DM-GX3-25 serial byte capture (``--format gx3raw``) into :class:`Samples`.

The capture is decoded through the same :class:`~imu_allan.device.gx3_stream.StreamParser` the
driver uses, so bad checksums, junk and truncated packets are handled identically.  The record
type carrying the most axes (and, among equals, the most packets) is used: accel + angular rate
records (0xC2, 0xC8, 0xCB, 0xCC) give all six axes; 0xCF (Euler + rate) alone gives the gyro
axes.  Other packets are skipped and listed in the warnings.

``t`` is the unwrapped device timer in seconds (62,500 ticks/s, rollovers added, a timer
reset bridged with the previous sample spacing); acceleration g -> m/s^2 with ``gravity``
(default 9.80665); angular rate rad/s; magnetic field, when present, in tesla in the extra
columns ``mag_x, mag_y, mag_z``.
"""

import numpy as np

from .samples import Samples
from ..core.checks.preprocess import count_gaps, nominal_interval
from ..core.units import AXES, GYRO_AXES, STANDARD_GRAVITY
from ..device.gx3_protocol import (
    decode_records,
    GAUSS_TO_TESLA,
    TICKS_PER_SECOND,
    ticks_to_seconds,
    TimerUnwrapper,
)
from ..device.gx3_stream import StreamParser
from ..errors import InputError

#: Record codes usable as IMU samples, best first: code -> axes it provides.
SAMPLE_CODES = {
    0xCC: AXES, 0xCB: AXES, 0xC8: AXES, 0xC2: AXES, 0xCF: GYRO_AXES,
}


def unwrap_ticks(raw_ticks, max_gap_ticks=600 * TICKS_PER_SECOND):
    """Unwrap a sequence of u32 timer values; return ``(ticks int64, rollovers, resets)``."""
    unwrapper = TimerUnwrapper(max_gap_ticks)
    out = np.fromiter((unwrapper.update(int(v)) for v in raw_ticks), dtype=np.int64,
                      count=len(raw_ticks))
    return out, unwrapper.rollovers, unwrapper.resets


def read_gx3raw(path, gravity=STANDARD_GRAVITY):
    """Decode a raw capture file; raise :class:`InputError` if it holds no usable packet."""
    try:
        with open(path, 'rb') as stream:
            data = stream.read()
    except OSError as exc:
        raise InputError(path, f'cannot read raw capture ({exc.strerror})') from None
    if not data:
        raise InputError(path, 'empty file')
    parser = StreamParser()
    packets = parser.feed(data) + parser.flush()
    stats = parser.stats
    by_code = {}
    for packet in packets:
        by_code.setdefault(packet[0], []).append(packet)
    usable = [c for c in SAMPLE_CODES if c in by_code]
    if not usable:
        found = ', '.join(f'0x{c:02X}' for c in sorted(by_code)) or 'none'
        raise InputError(path, f'no 3DM-GX3-25 IMU data packets found in {len(data)} bytes '
                               f'(packets found: {found})')
    code = max(usable, key=lambda c: (len(SAMPLE_CODES[c]), len(by_code[c])))
    axes = SAMPLE_CODES[code]
    warnings = []
    if stats.rejected_bytes:
        warnings.append(f'{stats.rejected_bytes} bytes rejected ({stats.bad_checksums} bad '
                        f'checksums, {stats.resyncs} resyncs)')
    for other in sorted(by_code):
        if other != code:
            warnings.append(f'{len(by_code[other])} packets of type 0x{other:02X} ignored '
                            f'(samples taken from 0x{code:02X})')
    rec = decode_records(code, by_code[code])
    ticks, rollovers, resets = unwrap_ticks(rec['timer'])
    if resets:
        warnings.append(f'device timer reset {resets} time(s): bridged with the previous '
                        'sample spacing')
    steps = np.diff(ticks)
    if np.any(steps > 0):
        # The device timer ticks evenly: lost packets show as steps of whole intervals.
        nominal = nominal_interval(steps[steps > 0])
        gaps, lost = count_gaps(steps, nominal)
        if lost:
            warnings.append(f'{int(gaps.sum())} gap(s) in the device timer: about {lost} '
                            'packet(s) missing')
    t = ticks_to_seconds(ticks)
    gyro = rec['gyro'].astype(np.float64)
    if axes == AXES:
        accel = rec['accel'].astype(np.float64) * gravity
        values = np.hstack([gyro, accel])
    else:
        values = gyro
    extra = {}
    if 'mag' in rec:
        mag = rec['mag'].astype(np.float64) * GAUSS_TO_TESLA
        for j, name in enumerate(('mag_x', 'mag_y', 'mag_z')):
            extra[name] = mag[:, j]
    return Samples(t=t, data=values, axes=tuple(axes), source=str(path), gravity=gravity,
                   warnings=warnings, extra=extra)
