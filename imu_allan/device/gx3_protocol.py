"""
LORD MicroStrain 3DM-GX3-25 single-byte protocol: command encoders and reply decoders.

ROS-free.  Byte layouts follow the DCP manual v1.14 (docs/references.md):

* commands start with a one-byte code, settings commands carry two "confirm intent" bytes,
  commands carry no checksum;
* replies have a fixed length per code; byte 0 echoes the code, the last two bytes are the
  unsigned 16-bit sum of all preceding bytes (big-endian);
* floats are IEEE-754 binary32 big-endian (unless the little-endian flag of the sampling
  settings is set), integers big-endian;
* data records end with a u32 timer at 62,500 ticks/s (16 us) that rolls over at 2**32.

Units as the device sends them: acceleration in g, angular rate in rad/s, magnetic field in
gauss, Euler angles in rad, timer in ticks.  Conversion to SI happens in the consumers
(``g * gravity`` -> m/s^2, gauss * 1e-4 -> tesla).
"""

from dataclasses import astuple, dataclass
import functools
import math
import struct

import numpy as np

#: Device timer rate, ticks per second.
TICKS_PER_SECOND = 62500
#: The timer is a u32: it wraps after 2**32 ticks (about 19.09 h).
TIMER_MODULUS = 1 << 32
#: Sampling base rate: output rate = BASE_RATE_HZ / decimation.
BASE_RATE_HZ = 1000.0
MIN_DECIMATION, MAX_DECIMATION = 1, 1000
#: Gauss -> tesla.
GAUSS_TO_TESLA = 1e-4
#: Baud rates the GX3-25 UART accepts (cmd 0xD9); 115200 is the default.
BAUD_RATES = (115200, 230400, 460800, 921600)
DEFAULT_BAUD = 115200
#: DCP-GX3 Table 5: minimum decimation per baud for 31-byte records.
TABLE_MIN_DECIMATION = {115200: 4, 230400: 3, 460800: 2, 921600: 1}
#: Serial bits per byte with 8N1 framing (start + 8 data + stop).
BITS_PER_BYTE = 10

# Data and reply codes.
RAW_ACCEL_RATE = 0xC1
ACCEL_RATE = 0xC2
DELTA_ANGLE_VELOCITY = 0xC3
SET_CONTINUOUS = 0xC4
ORIENTATION_MATRIX = 0xC5
ORIENTATION_UPDATE = 0xC6
MAG = 0xC7
ACCEL_RATE_MATRIX = 0xC8
ACCEL_RATE_MAG = 0xCB
ACCEL_RATE_MAG_MATRIX = 0xCC
CAPTURE_GYRO_BIAS = 0xCD
EULER = 0xCE
EULER_RATE = 0xCF
TEMPERATURES = 0xD1
STAB_ACCEL_RATE_MAG = 0xD2
DELTA_ANGLE_VELOCITY_MAG = 0xD3
MODE = 0xD4
MODE_PRESET = 0xD5
CONTINUOUS_PRESET = 0xD6
TIMER = 0xD7
COMM_SETTINGS = 0xD9
STATIONARY_TEST = 0xDA
SAMPLING_SETTINGS = 0xDB
REALIGN = 0xDD
QUATERNION = 0xDF
FIRMWARE_VERSION = 0xE9
DEVICE_ID = 0xEA
STOP_CONTINUOUS = 0xFA
DEVICE_RESET = 0xFE
ERROR = 0x21

#: The 3-byte reply to a command with wrong confirmation bytes.
ERROR_REPLY = b'\x21\x00\x21'

#: Total reply length (header .. checksum) per reply code.
REPLY_LENGTHS = {
    0xC1: 31, 0xC2: 31, 0xC3: 31, 0xC4: 8, 0xC5: 43, 0xC6: 43, 0xC7: 19, 0xC8: 67,
    0xC9: 19, 0xCA: 19, 0xCB: 43, 0xCC: 79, 0xCD: 19, 0xCE: 19, 0xCF: 31, 0xD0: 9,
    0xD1: 15, 0xD2: 43, 0xD3: 43, 0xD4: 4, 0xD5: 4, 0xD6: 4, 0xD7: 7, 0xD9: 10, 0xDA: 7,
    0xDB: 19, 0xDD: 7, 0xDF: 23, 0xE4: 5, 0xE5: 5, 0xE9: 7, 0xEA: 20, 0x21: 3,
}

#: Total command length (code .. last argument) per command code.
COMMAND_LENGTHS = {
    0xC1: 1, 0xC2: 1, 0xC3: 1, 0xC4: 4, 0xC5: 1, 0xC6: 1, 0xC7: 1, 0xC8: 1, 0xC9: 15,
    0xCA: 15, 0xCB: 1, 0xCC: 1, 0xCD: 5, 0xCE: 1, 0xCF: 1, 0xD0: 5, 0xD1: 1, 0xD2: 1,
    0xD3: 1, 0xD4: 4, 0xD5: 4, 0xD6: 4, 0xD7: 8, 0xD9: 11, 0xDA: 1, 0xDB: 20, 0xDD: 10,
    0xDF: 1, 0xE4: 8, 0xE5: 4, 0xE9: 1, 0xEA: 2, 0xFA: 3, 0xFE: 3,
}

#: Confirmation ("confirm user intent") bytes per command code.
CONFIRM = {
    0xC4: b'\xC1\x29', 0xCD: b'\xC1\x29', 0xD0: b'\xC1\x29', 0xD7: b'\xC1\x29',
    0xE4: b'\xC1\x29', 0xC9: b'\xB7\x44', 0xCA: b'\x12\xA5', 0xD4: b'\xA3\x47',
    0xD5: b'\xBA\x89', 0xD6: b'\xC6\x6B', 0xD9: b'\xC3\x55', 0xDB: b'\xA8\xB9',
    0xDD: b'\x54\x4C', 0xFA: b'\x75\xB4', 0xFE: b'\x9E\x3A',
}

#: Float fields of the data records, in wire order: name -> number of f32 values.
DATA_RECORDS = {
    0xC1: (('raw_accel', 3), ('raw_gyro', 3)),
    0xC2: (('accel', 3), ('gyro', 3)),
    0xC3: (('delta_angle', 3), ('delta_velocity', 3)),
    0xC5: (('matrix', 9),),
    0xC6: (('update_matrix', 9),),
    0xC7: (('mag', 3),),
    0xC8: (('accel', 3), ('gyro', 3), ('matrix', 9)),
    0xCB: (('accel', 3), ('gyro', 3), ('mag', 3)),
    0xCC: (('accel', 3), ('gyro', 3), ('mag', 3), ('matrix', 9)),
    0xCE: (('euler', 3),),
    0xCF: (('euler', 3), ('gyro', 3)),
    0xD2: (('stab_accel', 3), ('gyro', 3), ('stab_mag', 3)),
    0xD3: (('delta_angle', 3), ('delta_velocity', 3), ('mag', 3)),
    0xDF: (('quaternion', 4),),
}

#: Data-conditioning flag bits of the sampling settings (0xDB).
FLAG_ORIENTATION = 0x0001
FLAG_CONING_SCULLING = 0x0002
FLAG_LITTLE_ENDIAN = 0x0010
FLAG_SUPPRESS_NAN = 0x0020
FLAG_FINITE_SIZE = 0x0040
FLAG_DISABLE_MAG = 0x0100
FLAG_DISABLE_NORTH = 0x0400
FLAG_DISABLE_GRAVITY = 0x0800
FLAG_QUATERNION = 0x1000
DEFAULT_FLAGS = FLAG_ORIENTATION | FLAG_CONING_SCULLING
#: struct layout of the 0xDB settings (the :class:`SamplingSettings` fields in order), big-endian.
SAMPLING_LAYOUT = 'HHBBHHB'


def checksum(data):
    """Unsigned 16-bit sum of all bytes (wraps from 65535 to 0)."""
    return sum(data) & 0xFFFF


def with_checksum(body):
    """Append the big-endian 16-bit sum checksum to a reply body."""
    return bytes(body) + struct.pack('>H', checksum(body))


def checksum_ok(packet):
    """Return True when the last two bytes are the sum of all preceding ones."""
    return len(packet) >= 3 and (sum(packet[:-2]) & 0xFFFF) == (packet[-2] << 8 | packet[-1])


def timer_of(packet):
    """Return the u32 timer (ticks) of a record or timed reply (4 bytes before checksum)."""
    return struct.unpack_from('>I', packet, len(packet) - 6)[0]


def ticks_to_seconds(ticks):
    """Convert device timer ticks to seconds (62,500 ticks/s)."""
    return ticks / TICKS_PER_SECOND


# --------------------------------------------------------------------------------------------
# Data rate and bandwidth


def decimation_for_rate(rate_hz):
    """Decimation (1..1000) whose output rate 1000/decimation Hz is closest to ``rate_hz``."""
    if not rate_hz or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError(f'rate must be a positive number of Hz, got {rate_hz!r}')
    return min(MAX_DECIMATION, max(MIN_DECIMATION, int(round(BASE_RATE_HZ / rate_hz))))


def rate_for_decimation(decimation):
    """Output rate in Hz for a decimation."""
    return BASE_RATE_HZ / decimation


def min_decimation(baud, record_length=31):
    """
    Smallest decimation a baud rate can carry for records of ``record_length`` bytes.

    DCP-GX3 Table 5 gives the limit for 31-byte records; longer records are limited by the
    byte budget ``baud / 10`` bytes/s (8N1), e.g. 79-byte 0xCC records at 115200 baud: 7.
    """
    if baud not in TABLE_MIN_DECIMATION:
        raise ValueError(f'unsupported baud rate {baud} (supported: {BAUD_RATES})')
    bytes_per_s = baud / BITS_PER_BYTE
    by_bandwidth = math.ceil(BASE_RATE_HZ * record_length / bytes_per_s - 1e-9)
    return max(TABLE_MIN_DECIMATION[baud], by_bandwidth)


def max_rate(baud, record_length=31):
    """Highest output rate in Hz the baud rate can carry for records of that length."""
    return rate_for_decimation(min_decimation(baud, record_length))


# --------------------------------------------------------------------------------------------
# Command encoders (host -> device)


def _command(code, layout='', *values):
    """Encode command ``code``: its confirmation bytes (if any), then ``values`` by ``layout``."""
    return bytes([code]) + CONFIRM.get(code, b'') + struct.pack('>' + layout, *values)


def cmd_poll(code):
    """Encode a one-byte data command (poll one record), e.g. 0xC2, 0xCB, 0xCC, 0xCF."""
    if code not in DATA_RECORDS and code != TEMPERATURES:
        raise ValueError(f'0x{code:02X} is not a data command')
    return bytes([code])


def cmd_continuous(code):
    """Start streaming data command ``code`` (0 stops): ``C4 C1 29 cc``; 8-byte reply."""
    if code != 0 and code not in DATA_RECORDS:
        raise ValueError(f'0x{code:02X} is not a data command')
    return _command(SET_CONTINUOUS, 'B', code)


def cmd_stop_continuous():
    """Stop continuous mode silently: ``FA 75 B4`` (no reply)."""
    return _command(STOP_CONTINUOUS)


@dataclass
class SamplingSettings:
    """
    Content of the sampling-settings command/reply (0xDB).

    ``decimation``: output rate = 1000 Hz / decimation; ``flags``: data-conditioning bits;
    ``filter_window`` (gyro/accel) and ``mag_window``: 1..32 samples; ``up_compensation`` and
    ``north_compensation``: seconds, 1..1000; ``mag_power``: 0 high bandwidth, 1 low power.
    """

    decimation: int = 10
    flags: int = DEFAULT_FLAGS
    filter_window: int = 15
    mag_window: int = 17
    up_compensation: int = 10
    north_compensation: int = 10
    mag_power: int = 0

    @property
    def rate_hz(self):
        """Output rate, Hz."""
        return rate_for_decimation(self.decimation)

    def clamped(self):
        """Values clamped into the device's ranges, as the device does (DCP-GX3 §2 rule 6)."""
        def clamp(v, lo, hi):
            return min(hi, max(lo, int(v)))
        return SamplingSettings(
            clamp(self.decimation, MIN_DECIMATION, MAX_DECIMATION), int(self.flags) & 0xFFFF,
            clamp(self.filter_window, 1, 32), clamp(self.mag_window, 1, 32),
            clamp(self.up_compensation, 1, 1000), clamp(self.north_compensation, 1, 1000),
            clamp(self.mag_power, 0, 1))


def cmd_sampling_settings(settings=None, function=1):
    """
    Encode sampling settings 0xDB (20 bytes).

    ``function``: 0 read only (the settings are ignored and sent as zeros), 1 apply, 2 apply and
    store in non-volatile memory, 3 apply without reply.
    """
    if function not in (0, 1, 2, 3):
        raise ValueError('sampling settings function must be 0, 1, 2 or 3')
    if function == 0:
        return _command(SAMPLING_SETTINGS, 'B16x', 0)
    return _command(SAMPLING_SETTINGS, 'B' + SAMPLING_LAYOUT + '5x', function,
                    *astuple(settings or SamplingSettings()))


def cmd_read_sampling_settings():
    """Read the sampling settings without changing them."""
    return cmd_sampling_settings(function=0)


def cmd_comm_settings(baud=DEFAULT_BAUD, function=1, port=1, config=0x02):
    """
    Communications settings 0xD9 (11 bytes): ``function`` 0 read, 1 temporary, 2 stored.

    The reply comes at the old baud rate; the new one applies after it.
    """
    if function not in (0, 1, 2):
        raise ValueError('communications settings function must be 0, 1 or 2')
    return _command(COMM_SETTINGS, 'BBIBB', port, function, int(baud), config, 0)


def cmd_firmware_version():
    """Firmware version 0xE9 (7-byte reply)."""
    return _command(FIRMWARE_VERSION)


def cmd_device_id(selector):
    """Device identifier string 0xEA: 0 model number, 1 serial, 2 model name, 3 options, 4 lot."""
    if selector not in range(5):
        raise ValueError('device id selector must be 0..4')
    return _command(DEVICE_ID, 'B', selector)


def cmd_timer(function=0, value=0):
    """Timer 0xD7: function 0 read, 1 restart the timer at ``value`` ticks."""
    return _command(TIMER, 'BI', function, value)


# --------------------------------------------------------------------------------------------
# Reply encoders (device -> host): used by the simulator and by tests


def encode_record(code, values, timer, little_endian=False):
    """Encode a data record: header, f32 ``values`` (flat, wire order), u32 timer, checksum."""
    fields = DATA_RECORDS[code]
    n = sum(k for _, k in fields)
    values = list(values)
    if len(values) != n:
        raise ValueError(f'0x{code:02X} carries {n} floats, got {len(values)}')
    floats = struct.pack(('<' if little_endian else '>') + f'{n}f', *values)
    return with_checksum(bytes([code]) + floats + struct.pack('>I', timer % TIMER_MODULUS))


def encode_continuous_reply(code, timer):
    """Encode the 8-byte reply to ``C4 C1 29 cc``: ``C4 cc <u32 timer> <checksum>``."""
    return with_checksum(struct.pack('>BBI', SET_CONTINUOUS, code, timer % TIMER_MODULUS))


def encode_sampling_reply(settings):
    """Encode the 19-byte reply to 0xDB (the settings in effect)."""
    return with_checksum(struct.pack('>B' + SAMPLING_LAYOUT + '5x', SAMPLING_SETTINGS,
                                     *astuple(settings)))


def encode_comm_reply(baud, port=1, config=0x02):
    """Encode the 10-byte reply to 0xD9."""
    return with_checksum(struct.pack('>BBIBB', COMM_SETTINGS, port, int(baud), config, 0))


def encode_firmware_reply(version):
    """Encode the 7-byte reply to 0xE9; ``version`` is an integer (1130 = 1.1.30)."""
    return with_checksum(struct.pack('>BI', FIRMWARE_VERSION, int(version)))


def encode_device_id_reply(selector, text):
    """Encode the 20-byte reply to 0xEA: 16 ASCII characters, right-justified."""
    raw = str(text).encode('ascii')[-16:].rjust(16, b' ')
    return with_checksum(bytes([DEVICE_ID, selector]) + raw)


def encode_mode_reply(mode, code=MODE):
    """Encode the 4-byte reply to 0xD4/0xD5/0xD6."""
    return with_checksum(bytes([code, mode]))


def encode_timer_reply(timer):
    """Encode the 7-byte reply to 0xD7."""
    return with_checksum(struct.pack('>BI', TIMER, timer % TIMER_MODULUS))


# --------------------------------------------------------------------------------------------
# Reply decoders


@dataclass
class Record:
    """
    One decoded data record: ``code``, ``timer`` (ticks) and float ``fields`` by name.

    Field units as sent: accel g, gyro rad/s, mag gauss, euler rad, matrix dimensionless.
    """

    code: int
    timer: int
    fields: dict


def _check(packet, code, layout=''):
    """Check a ``code`` reply (length, header, checksum); unpack ``layout`` after its header."""
    if len(packet) != REPLY_LENGTHS[code] or packet[0] != code:
        raise ValueError(f'not a 0x{code:02X} reply ({len(packet)} bytes, header '
                         f'0x{packet[0] if packet else 0:02X})')
    if not checksum_ok(packet):
        raise ValueError(f'0x{code:02X} reply has a bad checksum')
    return struct.unpack_from('>' + layout, packet, 1)


def decode_record(packet, little_endian=False):
    """Decode one data record (any code of :data:`DATA_RECORDS`) into a :class:`Record`."""
    code = packet[0]
    if code not in DATA_RECORDS:
        raise ValueError(f'0x{code:02X} is not a data record')
    _check(packet, code)
    rec = np.frombuffer(packet, dtype=record_fields_dtype(code, little_endian))[0]
    fields = {name: tuple(rec[name].tolist()) for name, _ in DATA_RECORDS[code]}
    return Record(code, timer_of(packet), fields)


@functools.lru_cache(maxsize=None)
def record_fields_dtype(code, little_endian=False):
    """
    Structured dtype of one record with one field per value group.

    Fields: ``code`` (u1), one f4 sub-array per entry of :data:`DATA_RECORDS` (device units;
    big-endian unless ``little_endian``), ``timer`` (``>u4`` ticks), ``checksum``.
    """
    floats = ('<' if little_endian else '>') + 'f4'
    fields = [('code', 'u1')] + [(name, floats, (k,)) for name, k in DATA_RECORDS[code]]
    return np.dtype(fields + [('timer', '>u4'), ('checksum', '>u2')])


def record_array(code, data):
    """
    View concatenated records of one code (``bytes``, checksums verified) as a structured array.

    No copy: ``out['gyro']`` is an ``(n, 3)`` big-endian float32 view (device units) and
    ``out['timer']`` the u32 ticks; assigning them to float64/int64 arrays converts exactly.
    """
    return np.frombuffer(data, dtype=record_fields_dtype(code))


def decode_records(code, packets, little_endian=False):
    """
    Decode many records of one code at once (checksums must already be verified).

    ``packets`` is a list of records (bytes) or their concatenation.  Returns a dict with
    ``timer`` (n,) int64 ticks and one float32 array (n, k) per field of
    :data:`DATA_RECORDS` (device units).
    """
    buf = b''.join(packets) if isinstance(packets, (list, tuple)) else bytes(packets)
    arr = np.frombuffer(buf, dtype=record_fields_dtype(code, little_endian))
    out = {'timer': arr['timer'].astype(np.int64)}
    out.update((name, arr[name].astype(np.float32)) for name, _ in DATA_RECORDS[code])
    return out


def decode_continuous_reply(packet):
    """Return ``(code, timer)`` from the 8-byte 0xC4 reply."""
    return _check(packet, SET_CONTINUOUS, 'BI')


def decode_sampling_reply(packet):
    """Return the :class:`SamplingSettings` of a 19-byte 0xDB reply."""
    return SamplingSettings(*_check(packet, SAMPLING_SETTINGS, SAMPLING_LAYOUT))


def decode_comm_reply(packet):
    """Return ``(port, baud, config)`` from a 10-byte 0xD9 reply."""
    return _check(packet, COMM_SETTINGS, 'BIB')


def firmware_text(version):
    """``1130`` -> ``'1.1.30'`` (digit, digit, last two digits)."""
    digits = f'{int(version):04d}'
    return f'{int(digits[:-3])}.{digits[-3]}.{digits[-2:]}'


def decode_firmware_reply(packet):
    """Return ``(version_int, 'x.y.zz')`` from a 7-byte 0xE9 reply."""
    version, = _check(packet, FIRMWARE_VERSION, 'I')
    return version, firmware_text(version)


def decode_device_id_reply(packet):
    """Return ``(selector, text)`` from a 20-byte 0xEA reply (leading spaces stripped)."""
    selector, = _check(packet, DEVICE_ID, 'B')
    return selector, packet[2:18].decode('ascii', errors='replace').strip()


def decode_mode_reply(packet):
    """Return the mode byte of a 4-byte 0xD4/0xD5/0xD6 reply."""
    return _check(packet, packet[0], 'B')[0]


def decode_timer_reply(packet):
    """Return the timer ticks of a 7-byte 0xD7 reply."""
    return _check(packet, TIMER, 'I')[0]


# --------------------------------------------------------------------------------------------
# Temperatures (0xD1)

#: The four u16 channels of the 15-byte 0xD1 reply, in wire order (GX3-25 names; DCP-GX3
#: section "Temperatures"): the board sensor near the magnetometer, then three sensors read
#: through the gyro/accel channels.
TEMPERATURE_CHANNELS = ('mag', 'gyro_y_accel_x', 'gyro_x_accel_z_accel_y', 'gyro_z')
#: The channels are 12-bit ADC codes (0..4095) with a 3.0 V reference.
TEMPERATURE_ADC_MAX = 4095
TEMPERATURE_VREF_V = 3.0
# The constants of DCP-GX3 Eq. 15 (:func:`counts_to_celsius`).
_T_OFFSET_C = 1481.96
_T_SQUARE = 2.1962e6
_T_V0 = 1.8639
_T_K = 3.88e-6
#: Valid range of the sensor's calibration, deg C (DCP-GX3 Eq. 16).
TEMPERATURE_RANGE_C = (-40.0, 85.0)


@dataclass
class Temperatures:
    """
    A decoded 0xD1 reply.

    ``counts``: the 4 raw 12-bit codes in :data:`TEMPERATURE_CHANNELS` order; ``timer``:
    ticks.  Only the first channel has an absolute calibration; the others are relative.
    """

    counts: tuple
    timer: int

    @property
    def celsius(self):
        """Board temperature, deg C (DCP-GX3 Eq. 15 on the TemperatureMag channel)."""
        return counts_to_celsius(self.counts[0])


def counts_to_celsius(counts):
    """
    Convert TemperatureMag ADC counts to deg C with the exact form of DCP-GX3 Eq. 15.

    ``V = 3.0 * counts / 4096``; ``deg C = -1481.96 + sqrt(2.1962e6 + (1.8639 - V) / 3.88e-6)``
    (the linear form of Eq. 16, ``-(V - 1.8583) / 11.67e-3``, agrees within 0.7 deg C over
    -40..85 deg C).  One count is 0.058..0.068 deg C; the counts fall as it warms.  Arrays
    are converted element-wise.
    """
    volts = TEMPERATURE_VREF_V * np.asarray(counts, dtype=np.float64) / 4096.0
    out = -_T_OFFSET_C + np.sqrt(_T_SQUARE + (_T_V0 - volts) / _T_K)
    return float(out) if out.ndim == 0 else out


def celsius_to_counts(celsius):
    """Inverse of :func:`counts_to_celsius`, rounded to the nearest code and clipped to 12 bits."""
    c = np.asarray(celsius, dtype=np.float64)
    volts = _T_V0 - _T_K * ((c + _T_OFFSET_C) ** 2 - _T_SQUARE)
    out = np.clip(np.rint(volts * 4096.0 / TEMPERATURE_VREF_V), 0, TEMPERATURE_ADC_MAX)
    return int(out) if out.ndim == 0 else out.astype(np.int64)


def cmd_temperatures():
    """Poll the temperatures: the single byte ``D1`` (15-byte reply; also while streaming)."""
    return bytes([TEMPERATURES])


def encode_temperature_reply(counts, timer):
    """Encode the 15-byte 0xD1 reply: header, 4 x u16 counts, u32 timer, checksum."""
    counts = [int(c) for c in counts]
    if len(counts) != 4 or not all(0 <= c <= 0xFFFF for c in counts):
        raise ValueError(f'0xD1 carries four u16 counts, got {counts}')
    return with_checksum(struct.pack('>B4HI', TEMPERATURES, *counts, timer % TIMER_MODULUS))


def decode_temperature_reply(packet):
    """Return the :class:`Temperatures` of a 15-byte 0xD1 reply (ValueError if malformed)."""
    values = _check(packet, TEMPERATURES, '4HI')
    return Temperatures(values[:4], values[4])


# --------------------------------------------------------------------------------------------
# Timer unwrapping


class TimerUnwrapper:
    """
    Turn the u32 device timer into a monotonic 64-bit tick count.

    A backwards step whose forward distance modulo 2**32 is at most ``max_gap_ticks`` is a
    rollover (add 2**32).  A larger backwards step is a timer *reset* (power cycle, 0xD7): the
    true gap is unknowable, so the count continues one nominal period (the last positive
    step) after the previous value and :attr:`resets` counts it.  Forward steps are taken
    as they are (a long one is a gap in the data, not an error).
    """

    def __init__(self, max_gap_ticks=600 * TICKS_PER_SECOND):
        """``max_gap_ticks``: longest gap across which a backwards step counts as rollover."""
        self.max_gap_ticks = int(max_gap_ticks)
        self.offset = 0          # added to the raw ticks
        self.last_raw = None
        self.last = None         # last unwrapped value
        self.last_step = None    # last positive step, ticks
        self.rollovers = 0
        self.resets = 0

    def update(self, raw):
        """Unwrapped ticks of a raw u32 timer value; ``self.event`` tells what happened."""
        self.event = None
        if self.last_raw is not None and raw < self.last_raw:
            forward = raw + TIMER_MODULUS - self.last_raw
            if forward <= self.max_gap_ticks:
                self.offset += TIMER_MODULUS
                self.rollovers += 1
                self.event = 'rollover'
            else:
                self.offset = self.last + (self.last_step or 1) - raw
                self.resets += 1
                self.event = 'reset'
        value = raw + self.offset
        if self.last is not None and value > self.last and self.event != 'reset':
            self.last_step = value - self.last
        self.last_raw, self.last = raw, value
        return value

    def update_many(self, raw):
        """
        Unwrap a batch of raw u32 values at once; return ``(ticks, steps)`` or None.

        ``ticks``: the int64 array :meth:`update` would give value by value; ``steps``: the
        list of differences from the previous value (0 for the first value ever).  Only for a
        batch with no backward step (no rollover or reset: the usual case); for any other
        batch it returns None and changes nothing, and the caller takes it value by value.
        The steps are taken in plain Python: a batch is a few records, where each numpy call
        costs more than the whole loop.
        """
        values = raw.tolist()
        if not values:
            return None
        previous = values[0] if self.last_raw is None else self.last_raw
        steps = [b - a for a, b in zip([previous] + values, values)]
        if min(steps) < 0:
            return None
        ticks = raw + self.offset
        # The last positive step, as update() leaves it (the first value ever has step 0).
        for step in reversed(steps):
            if step:
                self.last_step = step
                break
        self.event = None
        self.last_raw, self.last = values[-1], values[-1] + self.offset
        return ticks, steps


def matrix_to_quaternion(matrix):
    """
    Quaternions ``(n, 4)`` as ``x, y, z, w`` of the device orientation matrices.

    ``matrix`` has shape ``(n, 9)`` (row-major M, as sent) or ``(n, 3, 3)``.  M maps earth to
    sensor (``v_sensor = M v_earth``), so the sensor's orientation in the earth frame is the
    rotation ``M^T``; that is what the quaternion describes (w >= 0, unit norm).
    """
    m = np.asarray(matrix, dtype=np.float64).reshape(-1, 3, 3)
    r = np.transpose(m, (0, 2, 1))
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = (
        [r[:, i, j] for j in range(3)] for i in range(3))
    traces = np.stack([1 + r00 + r11 + r22, 1 + r00 - r11 - r22,
                       1 - r00 + r11 - r22, 1 - r00 - r11 + r22], axis=1)
    # Shepperd's method: the largest of 4w^2, 4x^2, 4y^2, 4z^2 (case k) gives that component
    # s, the others are off-diagonal sums or differences divided by 4 s (numerically stable).
    k = np.argmax(traces, axis=1)
    rows = np.arange(len(k))
    s = 0.5 * np.sqrt(np.maximum(traces[rows, k], 1e-300))
    zero = np.zeros_like(r00)
    numerators = np.array([                             # (case, x y z w, row)
        (r21 - r12, r02 - r20, r10 - r01, zero),        # w largest
        (zero, r01 + r10, r02 + r20, r21 - r12),        # x largest
        (r01 + r10, zero, r12 + r21, r02 - r20),        # y largest
        (r02 + r20, r12 + r21, zero, r10 - r01)])       # z largest
    q = numerators[k, :, rows] / (4.0 * s)[:, None]
    q[rows, (k + 3) % 4] = s
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    return q
