"""
The simulated 3DM-GX3-25: its protocol state, noise, terminal, faults and run loop.

Used by the ``gx3_sim`` command (:mod:`imu_allan.cli.gx3_sim` and docs/driver.md describe the
behaviour) and by tests: ``Simulator(model, rate_hz=200.0, seed=1, ...)`` takes the
:class:`SimConfig` fields as keyword arguments.
"""

from dataclasses import dataclass
import errno
import math
import os
import select
import struct
import sys
import termios
import time
import tty
from typing import Union

import numpy as np

from . import gx3_protocol as p
from ..core.model import thesis_gx3_25_model
from ..core.simulation.device_processing import DeviceProcessing
from ..core.simulation.noise_stream import NoiseStream
from ..core.temperature import TemperatureProfile
from ..core.units import AXES, STANDARD_GRAVITY

JUNK_BYTES = bytes(b for b in range(256) if b not in p.REPLY_LENGTHS)
#: Field of the simulated magnetometer, gauss (a mid-latitude Earth field).
EARTH_FIELD_GAUSS = (0.20, 0.02, 0.45)
MAG_NOISE_GAUSS = 0.0005
TRUTH_COLUMNS = ('index', 'status', 'code', 'timer', 'accel_x', 'accel_y', 'accel_z',
                 'gyro_x', 'gyro_y', 'gyro_z', 'mag_x', 'mag_y', 'mag_z', 'm11', 'm12', 'm13',
                 'm21', 'm22', 'm23', 'm31', 'm32', 'm33', 'euler_roll', 'euler_pitch',
                 'euler_yaw', 'temperature_c')
#: The simulated gyro-side temperature channels of 0xD1: offsets (ADC codes) from the board
#: channel (they have no absolute calibration on the real unit either).
TEMPERATURE_CHANNEL_OFFSETS = (0, 40, -30, 10)
#: termios speed constants of the baud rates the device supports.
BAUD_CONSTANTS = {b: getattr(termios, f'B{b}') for b in p.BAUD_RATES}
#: What a receiver at the wrong baud rate makes of the bytes (a fixed scramble).
GARBLE = bytes((b * 77 + 13) % 256 for b in range(256))
ID_STRINGS = {0: '6223', 1: '6223.01234', 2: '3DM-GX3-25', 3: '5g 300d/s', 4: 'SIMULATED'}
#: Longest gyro/accel window 0xDB accepts (1..32, gx3_protocol.SamplingSettings.clamped): the
#: internal samples the noise stream keeps, so any window applies at once.
FILTER_WINDOW_MAX = 32


@dataclass
class SimConfig:
    """
    How the simulated device powers up and misbehaves (the ``gx3_sim`` options).

    Units: rates in Hz, times in s, probabilities per record; ``stream`` is a data command
    code (int, or hex text such as ``'C2'``) to stream from power-up.
    """

    gravity_axis: str = '-z'
    gravity: float = STANDARD_GRAVITY
    rate_hz: float = 100.0
    baud: int = p.DEFAULT_BAUD
    stream: Union[int, str] = None
    timer_start: int = 0
    seed: int = None
    link: str = None
    record_truth: str = None
    duration: float = None
    firmware: int = 1130
    serial: str = ID_STRINGS[1]
    ignore_host_baud: bool = False
    max_bias_delay: float = 0.2
    corrupt_rate: float = 0.0
    drop_rate: float = 0.0
    garbage_rate: float = 0.0
    stall_after: float = None
    stall_seconds: float = 2.0
    disconnect_after: float = None
    disconnect_seconds: float = 1.0
    temperature: str = 'constant:25'
    temperature_slope: str = None

    def check(self):
        """Validate the values; raise ValueError with a one-line reason (``--option``)."""
        for name in ('corrupt_rate', 'drop_rate', 'garbage_rate'):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f'--{name.replace("_", "-")} must be in [0, 1], got {value}')
        if not (math.isfinite(self.rate_hz) and 0 < self.rate_hz <= 1000):
            raise ValueError(f'--rate-hz must be in (0, 1000], got {self.rate_hz}')
        if self.baud not in p.BAUD_RATES:
            raise ValueError(f'--baud must be one of {", ".join(map(str, p.BAUD_RATES))}')
        if gravity_vector(self.gravity_axis) is None:
            raise ValueError(f'--gravity-axis must be x, y, z, -x, -y, -z or none, '
                             f'got {self.gravity_axis!r}')
        if self.stream is not None:
            try:
                code = self.stream if isinstance(self.stream, int) else int(self.stream, 16)
            except ValueError:
                code = -1
            if code not in p.DATA_RECORDS:
                raise ValueError(f'--stream must be a data command in hex (e.g. C2), '
                                 f'got {self.stream!r}')
            self.stream = code
        if not 0 <= self.timer_start < p.TIMER_MODULUS:
            raise ValueError('--timer-start must be in [0, 2**32)')
        for name in ('stall_after', 'stall_seconds', 'disconnect_after', 'disconnect_seconds',
                     'duration', 'max_bias_delay'):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f'--{name.replace("_", "-")} must be a number >= 0')
        try:
            self.profile = TemperatureProfile.parse(self.temperature or 'constant:25')
        except ValueError as exc:
            raise ValueError(f'--temperature {exc}') from None
        self.slopes = temperature_slopes(self.temperature_slope)


def temperature_slopes(text):
    """
    Bias-versus-temperature slopes in AXES order from ``--temperature-slope`` text.

    Three values (gyro x, y, z, rad/s per K) or six (then accel x, y, z, m/s^2 per K),
    comma-separated; None or '' gives zeros.  Raise ValueError with a one-line reason.
    """
    slopes = np.zeros(len(AXES))
    if not text:
        return slopes
    try:
        values = [float(x) for x in str(text).split(',')]
    except ValueError:
        values = []
    if len(values) not in (3, 6) or not all(math.isfinite(v) and abs(v) <= 1.0 for v in values):
        raise ValueError(f'--temperature-slope must be 3 or 6 comma-separated numbers (gyro '
                         f'rad/s/K, then accel m/s^2/K, each within +-1), got {text!r}')
    slopes[:len(values)] = values
    return slopes


def gravity_vector(axis):
    """Gravity reading in g for an axis name ('x', '-z', 'none'); None if the name is bad."""
    axis = str(axis).strip().lower()
    if axis == 'none':
        return np.zeros(3)
    sign = -1.0 if axis.startswith('-') else 1.0
    name = axis.lstrip('+-')
    if name not in ('x', 'y', 'z'):
        return None
    vec = np.zeros(3)
    vec['xyz'.index(name)] = sign
    return vec


def _f32(values):
    """Round to float32 (what goes on the wire) and return Python floats."""
    return [float(v) for v in np.asarray(values, dtype=np.float32)]


def processing_of(settings):
    """
    Return the unit's gyro/accel processing for its 0xDB settings (window and decimation).

    Not rounded here: the float32 rounding happens on the wire, after gravity is added.
    """
    return DeviceProcessing(p.BASE_RATE_HZ, settings.filter_window, settings.decimation,
                            output_dtype=None)


class NoiseSource:
    """
    Noise rows (gyro rad/s, accel m/s^2) of the simulated unit, in AXES order.

    One :class:`~imu_allan.core.simulation.noise_stream.NoiseStream` at the internal 1 kHz through
    the device's current window and decimation: the noise goes on across blocks and settings (no
    term restarts).  A change of settings drops the rest of the current block (at most
    ``BLOCK_SECONDS`` of sensor time skipped).
    """

    BLOCK_SECONDS = 1.0

    def __init__(self, model, seed):
        """Wrap a NoiseModel and a seed."""
        self.stream = NoiseStream(model, processing_of(p.SamplingSettings()), seed, axes=AXES,
                                  history=FILTER_WINDOW_MAX)
        self.key = None  # (window, decimation) of the block
        self.block = np.zeros((0, len(AXES)))
        self.i = 0

    def prime(self, settings):
        """Make a new block for ``settings`` now (at start: the first records are then on time)."""
        key = (settings.filter_window, settings.decimation)
        if key != self.key:
            self.stream.processing = processing_of(settings)
            self.key = key
        rate = self.stream.processing.output_rate_hz
        self.block = self.stream.take(max(1, round(self.BLOCK_SECONDS * rate)))
        self.i = 0

    def next(self, settings):  # noqa: A003 - the next noise sample
        """Next sample (6 values in AXES order) for the 0xDB ``settings`` in effect."""
        if (settings.filter_window, settings.decimation) != self.key \
                or self.i >= len(self.block):
            self.prime(settings)
        row = self.block[self.i]
        self.i += 1
        return row


class Device:
    """Protocol state of one powered-up 3DM-GX3-25 (no I/O: feed commands, take bytes)."""

    def __init__(self, cfg, noise, now, epoch=None):
        """
        Power up at host time ``now`` (monotonic seconds).

        ``epoch``: host time at which the temperature profile starts (default ``now``; a
        reset or reconnect keeps the simulator's, as a real unit keeps its temperature).
        """
        self.cfg = cfg
        self.epoch = now if epoch is None else epoch
        self.noise = noise
        self.power_on = now
        self.timer_start = cfg.timer_start
        self.settings = p.SamplingSettings(decimation=p.decimation_for_rate(cfg.rate_hz))
        self.baud = cfg.baud
        self.inbuf = bytearray()
        self.in_since = now
        self.stream_code = 0
        self.preset = 0
        self.mode_preset = 1
        self.delayed = []          # (due_time, reply bytes)
        self.pending_baud = None
        self.gravity_g = gravity_vector(cfg.gravity_axis)
        self.mag_rng = np.random.default_rng(None if cfg.seed is None else cfg.seed + 1)
        # 0xD1 polled while streaming: answered right after the next record (the order the
        # DCP manual gives for the GX2: the stream record first, then the polled reply).
        self.temperature_polls = 0
        if cfg.stream:
            self.start_stream(cfg.stream, now)

    # --- timing
    def ticks(self, now):
        """Device timer (u32 ticks) at host time ``now``."""
        return (self.timer_start + int((now - self.power_on) * p.TICKS_PER_SECOND)) \
            % p.TIMER_MODULUS

    @property
    def period(self):
        """Output period, s."""
        return self.settings.decimation / p.BASE_RATE_HZ

    def start_stream(self, code, now):
        """Start streaming ``code``: records at now + k * period."""
        self.stream_code = code
        self.k = 0
        self.stream_t0 = now
        self.stream_ticks0 = self.ticks(now)
        self.next_due = now + self.period

    def record_ticks(self, k):
        """Timer of streamed record k (k >= 1): 62.5 * decimation ticks apart (exactly)."""
        return (self.stream_ticks0 + (k * self.settings.decimation * 125) // 2) \
            % p.TIMER_MODULUS

    # --- temperature
    def temperature(self, now):
        """Board temperature, deg C, at host time ``now`` (the ``--temperature`` profile)."""
        return self.cfg.profile.at(now - self.epoch)

    def temperature_reply(self, now, timer):
        """Return the 15-byte 0xD1 reply for host time ``now`` and its deg C."""
        celsius = self.temperature(now)
        board = p.celsius_to_counts(celsius)
        counts = [min(p.TEMPERATURE_ADC_MAX, max(0, board + d))
                  for d in TEMPERATURE_CHANNEL_OFFSETS]
        return p.encode_temperature_reply(counts, timer), celsius

    # --- data
    def make_record(self, code, timer, now=None):
        """
        Build one data record; return ``(bytes, truth dict of float32 values)``.

        ``now`` (host time of the sample) sets the temperature, which shifts the biases by
        ``slope * (T - T_start)`` (``--temperature-slope``; T_start is the profile's start).
        """
        row = self.noise.next(self.settings)
        celsius = self.cfg.profile.start if now is None else self.temperature(now)
        shift = self.cfg.slopes * (celsius - self.cfg.profile.start)
        if shift.any():
            row = row + shift
        gyro = _f32(row[:3])
        accel = _f32(row[3:] / self.cfg.gravity + self.gravity_g)
        mag = _f32(np.asarray(EARTH_FIELD_GAUSS)
                   + MAG_NOISE_GAUSS * self.mag_rng.standard_normal(3))
        matrix = _f32(np.eye(3).ravel())
        euler = _f32(np.zeros(3))
        parts = {'accel': accel, 'gyro': gyro, 'mag': mag, 'matrix': matrix, 'euler': euler,
                 'raw_accel': accel, 'raw_gyro': gyro, 'delta_angle': gyro,
                 'delta_velocity': accel, 'stab_accel': accel, 'stab_mag': mag,
                 'update_matrix': matrix, 'quaternion': _f32([1, 0, 0, 0])}
        truth = {name: parts[name] for name, _ in p.DATA_RECORDS[code]}
        values = [v for group in truth.values() for v in group]
        truth['temperature_c'] = celsius
        return p.encode_record(code, values, timer), truth

    def due_records(self, now):
        """Yield ``(k, timer, bytes, truth)`` for streamed records due by ``now``."""
        while self.stream_code and self.next_due <= now:
            self.k += 1
            timer = self.record_ticks(self.k)
            data, truth = self.make_record(self.stream_code, timer, self.next_due)
            yield self.next_due, timer, data, truth
            self.next_due = self.stream_t0 + (self.k + 1) * self.period

    # --- commands
    def feed(self, data, now):
        """Process host bytes; return the list of replies (bytes) to send now."""
        if data:
            if not self.inbuf:
                self.in_since = now
            self.inbuf += data
        replies = []
        while self.inbuf:
            code = self.inbuf[0]
            length = p.COMMAND_LENGTHS.get(code)
            if length is None:
                del self.inbuf[0]          # unknown byte: ignored
                self.in_since = now
                continue
            if len(self.inbuf) < length:
                if now - self.in_since > 0.2:
                    del self.inbuf[0]      # truncated command: give up on it
                    self.in_since = now
                    continue
                break
            cmd = bytes(self.inbuf[:length])
            confirm = p.CONFIRM.get(code)
            if code == p.STOP_CONTINUOUS and cmd[1:3] != confirm:
                del self.inbuf[0]          # a bare FA (GX2 style) is ignored
                continue
            del self.inbuf[:length]
            self.in_since = now
            if confirm is not None and cmd[1:3] != confirm:
                replies.append(p.ERROR_REPLY)
                continue
            reply = self.command(cmd, now)
            if reply:
                replies.append(reply)
        return replies

    def command(self, cmd, now):
        """Execute one complete command; return its reply (or None)."""
        code = cmd[0]
        timer = self.ticks(now)
        if code == p.TEMPERATURES:
            if self.stream_code:
                self.temperature_polls += 1     # sent after the next record
                return None
            return self.temperature_reply(now, timer)[0]
        if code in p.DATA_RECORDS:
            return self.make_record(code, timer, now)[0]
        if code == p.SET_CONTINUOUS:
            cc = cmd[3]
            if cc == 0:
                self.stream_code = 0
            elif cc in p.DATA_RECORDS:
                self.start_stream(cc, now)
            return p.encode_continuous_reply(self.stream_code, timer)
        if code == p.STOP_CONTINUOUS:
            self.stream_code = 0
            return None
        if code == p.DEVICE_RESET:
            self.__init__(self.cfg, self.noise, now, self.epoch)
            return None
        if code == p.SAMPLING_SETTINGS:
            function = cmd[3]
            if function in (1, 2, 3):
                new = p.SamplingSettings(*struct.unpack_from('>' + p.SAMPLING_LAYOUT, cmd,
                                                             4)).clamped()
                changed = new.decimation != self.settings.decimation
                self.settings = new
                if changed and self.stream_code:
                    self.start_stream(self.stream_code, now)
                if function == 3:
                    return None
            return p.encode_sampling_reply(self.settings)
        if code == p.COMM_SETTINGS:
            port, function, baud = cmd[3], cmd[4], struct.unpack_from('>I', cmd, 5)[0]
            if port == 1 and function in (1, 2) and baud in p.BAUD_RATES:
                self.pending_baud = baud   # applies after the reply has gone out
                return p.encode_comm_reply(baud)
            return p.encode_comm_reply(self.baud)
        if code == p.FIRMWARE_VERSION:
            return p.encode_firmware_reply(self.cfg.firmware)
        if code == p.DEVICE_ID:
            sel = cmd[1]
            text = self.cfg.serial if sel == 1 else ID_STRINGS.get(sel, '')
            return p.encode_device_id_reply(sel, text)
        if code in (p.MODE, p.MODE_PRESET, p.CONTINUOUS_PRESET):
            return self.mode_command(code, cmd[3], now)
        if code == p.TIMER:
            function, value = struct.unpack_from('>BI', cmd, 3)
            if function == 1:
                self.timer_start, self.power_on = value, now
                timer = value
            return p.encode_timer_reply(timer)
        if code == p.CAPTURE_GYRO_BIAS:
            ms = struct.unpack_from('>H', cmd, 3)[0]
            due = now + min(ms / 1000.0, self.cfg.max_bias_delay)
            self.delayed.append((due, p.with_checksum(struct.pack('>B3fI', code, 0, 0, 0,
                                                                  self.ticks(due)))))
            return None
        if code in (0xC9, 0xCA):
            return p.with_checksum(cmd[:1] + cmd[3:15] + struct.pack('>I', timer))
        if code == 0xD0:
            return p.with_checksum(cmd[:1] + cmd[3:5] + struct.pack('>I', timer))
        if code in (p.STATIONARY_TEST, p.REALIGN):
            return p.with_checksum(bytes([code]) + bytes(4))
        if code in (0xE4, 0xE5):
            return p.with_checksum(bytes([code]) + bytes(2))
        return None

    def mode_command(self, code, m, now):
        """0xD4 mode, 0xD5 mode preset, 0xD6 continuous preset."""
        if code == p.CONTINUOUS_PRESET:
            if m in p.DATA_RECORDS:
                self.preset = m
            return p.encode_mode_reply(self.preset, code)
        if code == p.MODE_PRESET:
            if m in (1, 2, 3):
                self.mode_preset = m
            return p.encode_mode_reply(self.mode_preset, code)
        if m == 1 or m in (3, 4, 5):
            self.stream_code = 0
        elif m == 2 and self.preset:
            self.start_stream(self.preset, now)
        current = 2 if self.stream_code else 1
        return p.encode_mode_reply(current if m in (0, 1, 2) else m, code)

    def delayed_due(self, now):
        """Return replies whose delay has expired."""
        due = [r for t, r in self.delayed if t <= now]
        self.delayed = [(t, r) for t, r in self.delayed if t > now]
        return due


def _unless_idle(call, *args):
    """Return ``call(*args)``, or None when the pty would block or has no other end (EIO)."""
    try:
        return call(*args)
    except (BlockingIOError, InterruptedError):
        return None
    except OSError as exc:
        if exc.errno != errno.EIO:
            raise
        return None


class Terminal:
    """
    The pseudo-terminal pair.

    The simulator keeps a slave fd open so the port survives a driver closing and reopening it.
    """

    def __init__(self, link=None):
        """Open a pty in raw mode (and point ``link`` at it)."""
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.link = link
        if link:
            tmp = f'{link}.tmp{os.getpid()}'
            if os.path.lexists(tmp):
                os.unlink(tmp)
            os.symlink(self.path, tmp)
            os.replace(tmp, link)

    @property
    def name(self):
        """Return what a driver should open."""
        return self.link or self.path

    def read(self):
        """Bytes the host wrote (b'' if none)."""
        return _unless_idle(os.read, self.master, 4096) or b''

    def host_speed(self):
        """Return the termios output speed constant the host set (None if unknown)."""
        try:
            return termios.tcgetattr(self.master)[5]
        except termios.error:
            return None

    def write(self, data):
        """Write what fits; return the number of bytes written (0 when nobody reads)."""
        return _unless_idle(os.write, self.master, data) or 0

    def close(self):
        """Close both ends (the port vanishes) and remove the link."""
        if self.link and os.path.islink(self.link) and os.readlink(self.link) == self.path:
            os.unlink(self.link)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


class Truth:
    """CSV log of what was sent (float32 values printed exactly, device units)."""

    def __init__(self, path):
        """Open the file (or do nothing when path is None)."""
        self.stream = open(path, 'w', encoding='utf-8') if path else None
        self.index = 0
        self.last_flush = time.monotonic()
        if self.stream:
            self.stream.write('# gx3_sim truth: device units (accel g, gyro rad/s, mag gauss, '
                              'timer ticks at 62500/s); status ok, corrupted, dropped, '
                              'overrun, unread, reply, event (code 0 stall, 1 disconnect, '
                              '2 stream stopped by a command); temperature_c: deg C of the '
                              'profile at a record or a 0xD1 reply\n')
            self.stream.write(','.join(TRUTH_COLUMNS) + '\n')

    def row(self, status, code, timer, truth=None):
        """Append one row."""
        self.index += 1
        if not self.stream:
            return
        cols = [str(self.index), status, f'0x{code:02X}', str(timer)]
        truth = truth or {}
        for name, n in (('accel', 3), ('gyro', 3), ('mag', 3), ('matrix', 9), ('euler', 3)):
            vals = truth.get(name)
            cols += [repr(v) for v in vals] if vals else [''] * n
        celsius = truth.get('temperature_c')
        cols.append('' if celsius is None else repr(float(celsius)))
        self.stream.write(','.join(cols) + '\n')
        now = time.monotonic()
        if now - self.last_flush > 0.1:
            self.flush()
            self.last_flush = now

    def flush(self):
        """Flush to disk."""
        if self.stream:
            self.stream.flush()

    def close(self):
        """Flush and close."""
        if self.stream:
            self.stream.close()
            self.stream = None


class Simulator:
    """The run loop: terminal I/O, pacing, faults, truth log."""

    def __init__(self, model=None, **options):
        """
        Set up the terminal and the device.

        ``model`` defaults to the thesis 3DM-GX3-25 noise; ``options`` are the
        :class:`SimConfig` fields (or ``config=SimConfig(...)``), checked: ValueError if bad.
        """
        cfg = options.pop('config', None) or SimConfig(**options)
        cfg.check()
        model = model if model is not None else thesis_gx3_25_model()
        self.cfg = cfg
        self.rng = np.random.default_rng(None if cfg.seed is None else cfg.seed + 2)
        self.noise = NoiseSource(model, cfg.seed)
        self.truth = Truth(cfg.record_truth)
        self.term = Terminal(cfg.link)
        now = time.monotonic()
        self.device = Device(cfg, self.noise, now)
        # Generate the first noise block before announcing the port, so the first records
        # are not late.
        self.noise.prime(self.device.settings)
        self.line_free_at = now
        self.stream_time = 0.0       # seconds spent streaming (drives the fault schedule)
        self.stalled_until = None
        self.stalled_done = False
        self.disconnected_done = False

    def send(self, data, now):
        """Write bytes paced by the baud rate; return the status for the truth log."""
        start = max(now, self.line_free_at)
        if start - now > self.device.period + 1e-3:
            return 'overrun'
        self.line_free_at = start + len(data) * p.BITS_PER_BYTE / self.device.baud
        written = self.write(data)
        return 'ok' if written == len(data) else 'unread'

    def baud_matches(self):
        """Return False if the host opened the pty at a baud other than the device's."""
        if self.cfg.ignore_host_baud:
            return True
        speed = self.term.host_speed()
        return speed is None or speed == BAUD_CONSTANTS.get(self.device.baud)

    def write(self, data):
        """Write to the host (garbled when the baud rates differ)."""
        if not self.baud_matches():
            data = data.translate(GARBLE)
        return self.term.write(data)

    def send_reply(self, reply, now):
        """Send a command reply (and apply a pending baud change after it)."""
        self.write(reply)
        timed = reply[0] in (p.SET_CONTINUOUS, p.TIMER, p.TEMPERATURES)
        self.truth.row('reply', reply[0], p.timer_of(reply) if timed else 0)
        pending = self.device.pending_baud
        if pending:
            self.device.baud = pending
            self.device.pending_baud = None

    def stream_records(self, now):
        """Send every record due, applying the fault switches."""
        cfg = self.cfg
        for due, timer, data, truth in self.device.due_records(now):
            self.stream_time += self.device.period
            code = data[0]
            if cfg.drop_rate and self.rng.random() < cfg.drop_rate:
                self.truth.row('dropped', code, timer, truth)
                continue
            status = 'ok'
            garbage = bool(cfg.garbage_rate and self.rng.random() < cfg.garbage_rate)
            if garbage:
                junk = bytes(self.rng.choice(np.frombuffer(JUNK_BYTES, np.uint8),
                                             int(self.rng.integers(1, 33))))
                self.write(junk)
                self.truth.row('garbage', 0, len(junk))
            # Not both on one record: a damaged record right after junk looks like junk to
            # any framer, which would make the expected counters ambiguous.
            elif cfg.corrupt_rate and self.rng.random() < cfg.corrupt_rate:
                bad = bytearray(data)
                bad[int(self.rng.integers(1, len(data) - 2))] ^= int(self.rng.integers(1, 256))
                data = bytes(bad)
                status = 'corrupted'
            sent = self.send(data, due)
            self.truth.row(status if sent == 'ok' else sent, code, timer, truth)
            self.send_temperatures(due, timer)

    def send_temperatures(self, due, timer):
        """Answer the 0xD1 polls received while streaming, with the record's timer."""
        device = self.device
        while device.temperature_polls:
            device.temperature_polls -= 1
            reply, celsius = device.temperature_reply(due, timer)
            self.send(reply, due)
            self.truth.row('reply', reply[0], timer, {'temperature_c': celsius})

    def faults(self, now):
        """Stall and disconnect schedule (in seconds of streaming)."""
        cfg = self.cfg
        if (cfg.stall_after is not None and not self.stalled_done
                and self.stream_time >= cfg.stall_after):
            self.stalled_done = True
            self.stalled_until = now + cfg.stall_seconds
            self.truth.row('event', 0, self.device.ticks(now))
            self.say(f'stall {cfg.stall_seconds:g} s')
        if (cfg.disconnect_after is not None and not self.disconnected_done
                and self.stream_time >= cfg.disconnect_after):
            self.disconnected_done = True
            self.say('disconnect')
            self.term.close()
            self.truth.row('event', 1, 0)
            time.sleep(cfg.disconnect_seconds)
            self.term = Terminal(cfg.link)
            now = time.monotonic()
            # A freshly powered-up unit (at the temperature the old one had reached).
            self.device = Device(cfg, self.noise, now, self.device.epoch)
            self.line_free_at = now
            self.say(f'reconnected {self.term.path}')

    def say(self, text):
        """Progress line on stderr (stdout carries only the port path)."""
        print(f'gx3_sim: {text}', file=sys.stderr, flush=True)

    def run(self):
        """Serve until the duration is over or a signal arrives."""
        print(self.term.name, flush=True)
        end = None if self.cfg.duration is None else time.monotonic() + self.cfg.duration
        while True:
            now = time.monotonic()
            if end is not None and now >= end:
                return
            if self.stalled_until is not None:
                if now < self.stalled_until:
                    select.select([self.term.master], [], [], min(0.05, self.stalled_until - now))
                    self.term.read()        # a hung device loses what it is sent
                    self.device.inbuf.clear()
                    continue
                # The device wakes up: the timer kept running, the stream resumes from now.
                self.stalled_until = None
                if self.device.stream_code:
                    self.device.start_stream(self.device.stream_code, time.monotonic())
                self.say('stall over')
                continue
            wait = 0.05
            if self.device.stream_code:
                wait = min(wait, max(0.0, self.device.next_due - now))
            if self.device.delayed:
                wait = min(wait, max(0.0, min(t for t, _ in self.device.delayed) - now))
            ready, _, _ = select.select([self.term.master], [], [], wait)
            now = time.monotonic()
            data = self.term.read() if ready else b''
            if data and not self.baud_matches():
                data = b''      # framing errors: the device cannot read a wrong baud rate
            streaming = self.device.stream_code
            for reply in self.device.feed(data, now) + self.device.delayed_due(now):
                self.send_reply(reply, now)
            if streaming and not self.device.stream_code:  # a command stopped the stream
                self.truth.row('event', 2, self.device.ticks(now))
            self.stream_records(now)
            self.faults(now)

    def close(self):
        """Release the terminal and the truth file."""
        self.truth.close()
        self.term.close()
