"""
Serial transport to a 3DM-GX3-25 and the device session loop (ROS-free).

* :class:`SerialLink`: open/read/write/close a pyserial port; every failure becomes a
  :class:`LinkError` with a one-line reason.
* :class:`Backoff`: retry delays doubling from ``initial`` up to ``maximum`` seconds.
* :class:`TimeSync`: device timer -> host clock mapping (method below).
* :class:`Gx3Session`: the loop a driver runs in a thread: open the port (with back-off),
  configure the device (stop, identify, sampling settings, continuous mode), read and frame the
  stream, detect gaps, stalls and vanished ports, and recover from all of them.  Decoded
  batches go to a callback; nothing here imports ROS.

Time stamping (:class:`TimeSync`; docs/driver.md, section "Time stamps", gives the method and
its consequences): the unwrapped device timer ``d`` (s) is mapped to the host clock as
``d + o``, the offset ``o`` following ``T = min(h - d)`` over the last ``window`` seconds, ``h``
each record's host arrival time (the passive synchronisation of Olson, IROS 2010), moving at
most ``max_slew`` s per s of device time and re-anchored at once after a discontinuity or a
jump above ``jump_threshold``.
"""

from collections import deque
from dataclasses import dataclass
import math
import os
import select
import threading
import time
from typing import Callable

import numpy as np

from . import gx3_protocol as p
from .gx3_stream import StreamParser
from ..core.checks.preprocess import count_gaps, GAP_FACTOR


class LinkError(Exception):
    """The serial port cannot be opened, has vanished or failed; the message is one line."""


class SerialLink:
    """A pyserial port (8N1, no flow control, raw) with errors mapped to :class:`LinkError`."""

    #: Most bytes taken per read (more than a tty buffer holds).
    CHUNK = 65536

    def __init__(self, port, baud, read_timeout=0.05):
        """Remember the settings; nothing is opened yet."""
        self.port = port
        self.baud = int(baud)
        self.read_timeout = read_timeout
        self.serial = None

    @property
    def is_open(self):
        """Return True while the port is open."""
        return self.serial is not None

    def open(self):  # noqa: A003 - the link's own verb, as pyserial names it
        """Open the port; discard anything received before this moment."""
        import serial
        self.close()
        try:
            self.serial = serial.Serial(self.port, self.baud, bytesize=8, parity='N',
                                        stopbits=1, timeout=self.read_timeout,
                                        write_timeout=1.0, xonxoff=False, rtscts=False)
            self.serial.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as exc:
            self.serial = None
            raise LinkError(f'{self.port}: cannot open ({_reason(exc)})') from None

    def set_baud(self, baud):
        """Change the host-side baud rate of the open port."""
        self.baud = int(baud)
        if self.serial is not None:
            try:
                self.serial.baudrate = self.baud
            except Exception as exc:  # pyserial raises several types here
                raise LinkError(f'{self.port}: cannot set baud {baud} ({_reason(exc)})') \
                    from None

    def read(self):
        """
        Return the bytes waiting (after waiting up to ``read_timeout`` for the first).

        On a POSIX port (pyserial opens it non-blocking) this is one ``os.read`` when data are
        waiting, the usual case at a high rate: pyserial's ``in_waiting`` + ``read`` cost three
        system calls and a select per read.  Other ports go through pyserial.
        """
        fd = getattr(self.serial, 'fd', None)
        if fd is None:
            return self._read_pyserial()
        try:
            data = os.read(fd, self.CHUNK)
            if data:
                return data
            # Nothing waiting (a raw tty with VMIN 0 reads b''): wait for the first byte as
            # pyserial's read would.
            if not select.select([fd], [], [], self.read_timeout)[0]:
                return b''
            data = os.read(fd, self.CHUNK)
        except BlockingIOError:
            return b''
        except OSError as exc:
            raise LinkError(f'{self.port}: read failed ({_reason(exc)})') from None
        if not data:
            # Ready but nothing to read: a hang-up (pyserial says the same).
            raise LinkError(f'{self.port}: read failed (device reports readiness to read but '
                            f'returned no data: disconnected)')
        return data

    def _read_pyserial(self):
        import serial
        try:
            waiting = self.serial.in_waiting
            return self.serial.read(max(1, waiting))
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise LinkError(f'{self.port}: read failed ({_reason(exc)})') from None

    def write(self, data):
        """Write all bytes."""
        import serial
        try:
            self.serial.write(data)
        except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
            raise LinkError(f'{self.port}: write failed ({_reason(exc)})') from None

    def close(self):
        """Close the port (never raises)."""
        if self.serial is not None:
            try:
                self.serial.close()
            except Exception:  # closing a vanished port may fail in many ways; ignore
                pass
            self.serial = None


def _reason(exc):
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


class Backoff:
    """Retry delays: ``initial``, doubled after each failure, capped at ``maximum`` (s)."""

    def __init__(self, initial=0.25, maximum=5.0):
        """Start at ``initial`` seconds."""
        self.initial = initial
        self.maximum = maximum
        self.delay = initial

    def next(self):  # noqa: A003 - the next delay, as iterators name it
        """Return the delay to wait now and double the next one."""
        delay = self.delay
        self.delay = min(self.maximum, self.delay * 2.0)
        return delay

    def reset(self):
        """After a success: back to the initial delay."""
        self.delay = self.initial


class TimeSync:
    """Map device seconds to host seconds with even spacing (see the module docstring)."""

    def __init__(self, max_slew=5e-4, window=10.0, jump_threshold=0.5):
        """``max_slew``: s/s; ``window``: s of device time; ``jump_threshold``: s."""
        self.max_slew = max_slew
        self.window = window
        self.jump_threshold = jump_threshold
        self.jumps = 0
        self.epoch = None
        self.reset()

    def reset(self):
        """Forget the mapping (after a reconnect, a stall or a timer reset)."""
        self.offset = None
        self.last_device = None
        self.minima = deque()

    def stamps(self, device_s, host_s):
        """
        Host-clock stamps, integer ns, for device times ``device_s`` received at ``host_s``.

        Internally times are relative to a whole-second epoch of the host clock, so float64
        keeps sub-nanosecond resolution (absolute epoch seconds would round to 0.24 us).
        """
        device_s = np.asarray(device_s, dtype=np.float64)
        host_s = np.asarray(host_s, dtype=np.float64)
        if self.epoch is None:
            self.epoch = int(math.floor(host_s[0]))
        first, end = float(device_s[0]), float(device_s[-1])
        if self.last_device is not None and first < self.last_device:
            # The device time went back (timer reset): the old minima mean nothing now.
            self.reset()
            self.jumps += 1
        # (ufunc calls, not the array methods or np.clip/np.round wrappers: the batches are
        # small, so call overhead is most of the cost; the arithmetic is the same.)
        batch_min = float(np.minimum.reduce((host_s - self.epoch) - device_s))
        # Sliding-window minimum (monotonic deque: values increase from left to right), O(1)
        # per batch however many batches the window holds.
        minima = self.minima
        while minima and minima[-1][1] >= batch_min:
            minima.pop()
        minima.append((end, batch_min))
        while minima[0][0] < end - self.window:
            minima.popleft()
        target = minima[0][1]
        if self.offset is None or abs(target - self.offset) > self.jump_threshold:
            if self.offset is not None:
                self.jumps += 1
            self.offset = target
            self.last_device = first
        # offsets = offset + clip(target - offset, -allowed, allowed), allowed growing with
        # the device time since the last stamp: a scalar when even the smallest allowance
        # covers the whole move (the usual case once converged), else element-wise.
        move = target - self.offset
        least = float(np.minimum.reduce(device_s)) - self.last_device
        if abs(move) <= self.max_slew * max(least, 0.0):
            offsets = self.offset + move
            self.offset = offsets
        else:
            allowed = self.max_slew * np.maximum(device_s - self.last_device, 0.0)
            step = np.minimum(allowed, abs(move))
            offsets = self.offset + step if move >= 0 else self.offset - step
            self.offset = float(offsets[-1])
        self.last_device = end
        return np.rint((device_s + offsets) * 1e9).astype(np.int64) + self.epoch * 10**9

    def stamp_at(self, device_s):
        """
        Host-clock stamp, integer ns, of one device time with the current offset.

        None before the first :meth:`stamps` (no mapping yet).  Changes nothing: for
        occasional replies, such as the temperatures, that must not move the offset the
        records follow.
        """
        if self.offset is None or self.epoch is None:
            return None
        return int(round((float(device_s) + float(self.offset)) * 1e9)) + self.epoch * 10**9


#: Driver modes -> streamed data command.
MODES = {
    'accel_rate': p.ACCEL_RATE,
    'accel_rate_mag': p.ACCEL_RATE_MAG,
    'accel_rate_orientation': p.ACCEL_RATE_MATRIX,
    'accel_rate_mag_orientation': p.ACCEL_RATE_MAG_MATRIX,
}


def check_rate(rate_hz, baud, mode):
    """
    Validate a rate for a baud rate and mode; return ``(decimation, flags)``.

    Raise ValueError with a user-facing reason when the link cannot carry the rate (DCP-GX3
    Table 5, extended to longer records by the byte budget) or when orientation is asked for
    above 500 Hz.
    """
    if baud not in p.BAUD_RATES:
        raise ValueError(f'baud {baud} is not supported (use one of '
                         f'{", ".join(map(str, p.BAUD_RATES))})')
    if mode not in MODES:
        raise ValueError(f'mode {mode!r} is unknown (use one of {", ".join(MODES)})')
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= p.BASE_RATE_HZ):
        raise ValueError(f'rate_hz {rate_hz} is outside (0, 1000] Hz')
    code = MODES[mode]
    decimation = p.decimation_for_rate(rate_hz)
    length = p.REPLY_LENGTHS[code]
    lowest = p.min_decimation(baud, length)
    if decimation < lowest:
        faster = [b for b in p.BAUD_RATES if p.min_decimation(b, length) <= decimation]
        hint = f'; use baud {faster[0]}' if faster else ''
        raise ValueError(f'rate_hz {rate_hz:g} is too high for {baud} baud with {length}-byte '
                         f'{mode} records: at most {p.rate_for_decimation(lowest):.4g} Hz'
                         f'{hint}')
    orientation = 'orientation' in mode
    if orientation and decimation < 2:
        raise ValueError(f'rate_hz {rate_hz:g}: orientation is only computed up to 500 Hz')
    # 1000 Hz needs the orientation calculation off (DCP-GX3 Table 5).
    flags = p.DEFAULT_FLAGS if decimation >= 2 else p.FLAG_CONING_SCULLING
    return decimation, flags


@dataclass
class SessionStats:
    """Counters of a session (read by the driver's diagnostics; ints only, no lock needed)."""

    records: int = 0
    dropped: int = 0
    stalls: int = 0
    reconnects: int = 0
    opens: int = 0
    setups: int = 0
    setup_failures: int = 0
    timer_resets: int = 0
    rollovers: int = 0
    internal_errors: int = 0
    temperatures: int = 0


@dataclass(frozen=True)
class SessionHooks:
    """What a :class:`Gx3Session` calls (from its thread): see the class docstring."""

    on_batch: Callable
    clock: Callable = time.time
    log: Callable = None
    on_temperature: Callable = None


@dataclass(frozen=True)
class SessionOptions:
    """
    How a :class:`Gx3Session` runs; times in s.

    No record for ``stall_timeout``: reconnect; the wait for a reply; the pause between reads;
    0xD1 every ``temperature_period`` (0: never); the 0xDB filter window (taps); a raw capture
    file (None: none); the reconnect delays.
    """

    stall_timeout: float = 1.0
    reply_timeout: float = 0.3
    poll_interval: float = 0.005
    temperature_period: float = 0.0
    filter_window: int = 15
    record_raw: str = None
    backoff: Backoff = None  # None: Backoff()


class Gx3Session:
    """
    Talk to one 3DM-GX3-25 on a serial port and deliver decoded batches.

    ``hooks`` (:class:`SessionHooks`): ``on_batch(code, records, stamps)`` is called from the
    session thread with ``records``
    from :func:`~imu_allan.device.gx3_protocol.record_array` (a structured array: fields by
    name, device units) and host-clock ``stamps`` (int64 nanoseconds).  ``clock()`` returns
    host seconds (the driver passes its ROS clock).  ``log(level, text)`` reports events
    (level 'info', 'warn', 'error').

    Temperatures: every ``temperature_period`` s (0 = never) while streaming, the session
    sends 0xD1; the device answers between two data records, the framer picks the reply out
    of the stream (no record is lost), and ``on_temperature(reading, stamp_ns)`` gets the
    decoded :class:`~imu_allan.device.gx3_protocol.Temperatures` and the host-clock stamp of
    its timer (mapped like the records', or the host clock before the first record).
    """

    def __init__(self, port, baud, mode, rate_hz, hooks, options=None):
        """Configure (``options``: :class:`SessionOptions`); then :meth:`run`, :meth:`stop`."""
        opt = options or SessionOptions()
        self.decimation, self.flags = check_rate(rate_hz, baud, mode)
        self.filter_window = int(opt.filter_window)
        self.sampling = None  # the 0xDB settings the device confirmed (SamplingSettings)
        self.code = MODES[mode]
        self.baud = baud
        self.link = SerialLink(port, baud)
        self.on_batch, self.clock = hooks.on_batch, hooks.clock
        self.log = hooks.log or (lambda level, text: None)
        self.stall_timeout = opt.stall_timeout
        self.reply_timeout = opt.reply_timeout
        self.poll_interval = opt.poll_interval
        self.sync = TimeSync()
        self.backoff = opt.backoff or Backoff()
        self.parser = StreamParser()
        self.unwrapper = p.TimerUnwrapper()
        self.stats = SessionStats()
        self.expected_step = self.decimation * p.TICKS_PER_SECOND / p.BASE_RATE_HZ
        # Only a batch with a step above this can hold a gap (count_gaps' rule).
        self.gap_step = GAP_FACTOR * self.expected_step
        self.raw = open(opt.record_raw, 'ab') if opt.record_raw else None
        self.state = 'starting'
        self.last_error = ''
        self.firmware = ''
        self.model = ''
        self.serial_number = ''
        self._stop = threading.Event()
        # False: every batch goes record by record through TimerUnwrapper.update, the path
        # batches with a rollover or reset take (a reference for tests).
        self.vectorized = True
        self._replies = deque()
        self._last_read = 0.0  # host time of the last read with data (s)
        self.thread = None
        self.temperature_period = float(opt.temperature_period or 0.0)
        self.on_temperature = hooks.on_temperature
        self.last_temperature_c = math.nan
        self._next_temperature = 0.0

    # ------------------------------------------------------------------ thread control
    def start(self):
        """Run the session in a daemon thread."""
        self.thread = threading.Thread(target=self.run, name='gx3_session', daemon=True)
        self.thread.start()

    def stop(self, timeout=5.0):
        """
        Ask the loop to end, stop continuous mode and close the port.

        The loop sends the stop command on its way out; the timeout is generous because the
        process exits (ending this daemon thread) once it returns, and a device left streaming
        would keep sending into a closed port (seen under load with 2 s).
        """
        self._stop.set()
        if self.thread is not None:
            self.thread.join(timeout)

    def _wait(self, seconds):
        return self._stop.wait(seconds)

    def _nap(self):
        # One poll interval between reads.  time.sleep, not Event.wait: a timed wait on the
        # event's condition costs about twice the CPU per wake-up (110 vs 57 us measured here),
        # and stop() only waits one interval (at most 0.1 s) longer for it.
        time.sleep(self.poll_interval)

    # ------------------------------------------------------------------ main loop
    def run(self):
        """Open, configure, stream, recover; until :meth:`stop`."""
        needs_setup = True
        last_data = 0.0
        try:
            while not self._stop.is_set():
                if not self.link.is_open:
                    if not self._open():
                        continue
                    needs_setup = True
                try:
                    if needs_setup:
                        if not self._setup():
                            self.stats.setup_failures += 1
                            # Keep reading while backing off: a device that resumes on its
                            # own (end of a stall) is taken as it comes, nothing is lost.
                            if not self._idle(self.backoff.next()):
                                continue
                            self.log('info', f'{self.link.port}: streaming again')
                        needs_setup, last_data = False, time.monotonic()
                        self.state = 'streaming'
                    got = self._pump()
                    now = time.monotonic()
                    if self.temperature_period > 0 and now >= self._next_temperature:
                        # Polled between records: the reply is framed out of the stream.
                        self.link.write(p.cmd_temperatures())
                        self._next_temperature = now + self.temperature_period
                    if got:
                        last_data = now
                        self.backoff.reset()
                        if self.state != 'streaming':
                            self.log('info', f'{self.link.port}: streaming again')
                        self.state = 'streaming'
                    elif now - last_data > self.stall_timeout:
                        self.stats.stalls += 1
                        self.state = 'stalled'
                        self.last_error = (f'no data for {now - last_data:.1f} s '
                                           f'(device stalled or unplugged)')
                        self.log('warn', f'{self.link.port}: {self.last_error}, reconfiguring')
                        self._new_epoch()
                        needs_setup = True
                        last_data = now
                    self._nap()
                except LinkError as exc:
                    self._lost(str(exc))
                except Exception as exc:  # noqa: B902 - a bug must not end the data stream
                    self.stats.internal_errors += 1
                    self._lost(f'{self.link.port}: internal error {type(exc).__name__}: '
                               f'{exc}')
        finally:
            self._shutdown()

    def _idle(self, seconds):
        """Wait ``seconds`` while still reading; return True if data records arrived."""
        end = time.monotonic() + seconds
        got = 0
        while not self._stop.is_set() and time.monotonic() < end:
            got += self._pump()
            if got:
                return True
            self._nap()
        return False

    def _open(self):
        try:
            self.link.set_baud(self.baud)
            self.link.open()
        except LinkError as exc:
            self.state = 'port unavailable'
            if str(exc) != self.last_error:
                self.log('error', f'{exc}; retrying with back-off')
            self.last_error = str(exc)
            self._wait(self.backoff.next())
            return False
        self.stats.opens += 1
        if self.stats.opens > 1:
            self.stats.reconnects += 1
        self._flush_parser()
        self._new_epoch()
        self.log('info', f'{self.link.port}: opened at {self.link.baud} baud')
        return True

    def _lost(self, reason):
        self.state = 'port lost'
        self.last_error = reason
        self.log('error', f'{reason}; reopening with back-off')
        self.link.close()
        self._flush_parser()
        self._new_epoch()

    def _flush_parser(self):
        """
        End the byte stream of a port that closed: deliver what the parser still holds.

        As :func:`~imu_allan.device.gx3_stream.parse_bytes` ends a capture
        (:meth:`StreamParser.flush`): the good records held back behind a header-like byte
        are delivered (stamped by the last read), the rest counted in ``rejected_bytes``.
        """
        packets = self.parser.flush()
        if packets:
            self._take(packets, self._last_read)
        self._wait(self.backoff.next())

    def _new_epoch(self):
        """Mark a discontinuity: the next record starts a new gap reference and time anchor."""
        self.unwrapper = p.TimerUnwrapper()
        self.sync.reset()

    def _shutdown(self):
        if self.link.is_open:
            try:
                # Leave the device quiet, as the reference drivers do.
                self.link.write(p.cmd_stop_continuous())
                time.sleep(0.02)
            except LinkError:
                pass
            self.link.close()
        if self.raw is not None:
            self.raw.close()
            self.raw = None
        self.state = 'stopped'

    # ------------------------------------------------------------------ reading
    def _pump(self):
        """Read once, frame, deliver data records; return the number of records."""
        data = self.link.read()
        if not data:
            return 0
        host = self._last_read = self.clock()
        if self.raw is not None:
            self.raw.write(data)
        return self._take(self.parser.feed(data), host)

    def _take(self, packets, host):
        """Deliver the data records of ``packets`` (read at ``host`` s); keep replies."""
        if not packets:
            return 0
        byte_time = p.BITS_PER_BYTE / self.link.baud
        # Host arrival time of each record: the clock after the read minus the time the bytes
        # after it took on the wire (the parser keeps unfinished bytes buffered).
        later = self.parser.buffered + sum(map(len, packets))
        code = self.code
        records, times, temperatures = [], [], []
        for packet in packets:
            later -= len(packet)
            if packet[0] == code:
                records.append(packet)
                times.append(host - later * byte_time)
            elif packet[0] == p.TEMPERATURES:
                temperatures.append(packet)
            else:
                self._replies.append(packet)
        if records:
            self._deliver(b''.join(records), np.array(times))
        for packet in temperatures:
            self._temperature(packet, host)
        return len(records)

    def _temperature(self, packet, host):
        """Decode a 0xD1 reply, stamp its timer like the records and hand it over."""
        reading = p.decode_temperature_reply(packet)
        self.stats.temperatures += 1
        self.last_temperature_c = reading.celsius
        if self.on_temperature is None:
            return
        stamp = None
        last = self.unwrapper.last
        if last is not None:
            # The reply's timer is within a record or two of the last record's: unwrap it
            # against that one (a rollover between them is 2**32 ticks away either way).
            ticks = reading.timer + self.unwrapper.offset
            if ticks < last - p.TIMER_MODULUS // 2:
                ticks += p.TIMER_MODULUS
            elif ticks > last + p.TIMER_MODULUS // 2:
                ticks -= p.TIMER_MODULUS
            stamp = self.sync.stamp_at(p.ticks_to_seconds(ticks))
        if stamp is None:
            stamp = int(round(host * 1e9))
        self.on_temperature(reading, stamp)

    def _deliver(self, block, host_times):
        """Decode, unwrap, count gaps, stamp and hand over the records in ``block`` (bytes)."""
        rec = p.record_array(self.code, block)
        raw = rec['timer'].astype(np.int64)
        # The gap reference (the last record's ticks) is the unwrapper's last value.
        unwrapped = self.unwrapper.update_many(raw) if self.vectorized else None
        ticks, steps = unwrapped or self._unwrap_each(raw)
        if steps and max(steps) > self.gap_step:
            self.stats.dropped += count_gaps(steps, self.expected_step)[1]
        # Unwrapped ticks never decrease, so one TimeSync call stamps the whole batch.
        stamps = self.sync.stamps(p.ticks_to_seconds(ticks), host_times)
        self.stats.records += len(raw)
        self.on_batch(self.code, rec, stamps)

    def _unwrap_each(self, raw):
        """
        Unwrap record by record (a batch with a rollover or timer reset).

        Return ``(ticks, steps)`` like :meth:`TimerUnwrapper.update_many`, the steps without
        a reset's: its length is unknown, so it is no gap; a reset also re-anchors the time
        sync.
        """
        u = self.unwrapper
        ticks = np.empty(len(raw), dtype=np.int64)
        steps = []
        for i, value in enumerate(raw.tolist()):
            last = u.last
            ticks[i] = tick = u.update(value)
            if u.event == 'reset':
                self.stats.timer_resets += 1
                self.sync.reset()
            elif u.event == 'rollover':
                self.stats.rollovers += 1
            if last is not None and u.event != 'reset':
                steps.append(tick - last)
        return ticks, steps

    # ------------------------------------------------------------------ configuration
    def _request(self, command, code, check=None):
        """Send a command and wait for its reply (data records keep flowing meanwhile)."""
        self._replies.clear()
        self.link.write(command)
        deadline = time.monotonic() + self.reply_timeout
        while time.monotonic() < deadline and not self._stop.is_set():
            self._pump()
            while self._replies:
                reply = self._replies.popleft()
                if reply[0] == code and (check is None or check(reply)):
                    return reply
        return None

    def _setup(self):
        """Stop, identify, set the rate, start continuous mode; True on success."""
        self.state = 'configuring'
        self.stats.setups += 1
        self.link.write(p.cmd_stop_continuous())
        # Let a running stream drain; its records are still delivered.
        end = time.monotonic() + 0.05
        while time.monotonic() < end:
            self._pump()
        reply = self._request(p.cmd_firmware_version(), p.FIRMWARE_VERSION)
        if reply is None and self.baud != p.DEFAULT_BAUD:
            reply = self._change_baud()
        if reply is None:
            self.last_error = 'device does not answer (firmware query 0xE9 timed out)'
            self.log('warn', f'{self.link.port}: {self.last_error}')
            return False
        self.firmware = p.decode_firmware_reply(reply)[1]
        for selector, attr in ((2, 'model'), (1, 'serial_number')):
            reply = self._request(p.cmd_device_id(selector), p.DEVICE_ID,
                                  lambda r, s=selector: r[1] == s)
            if reply is not None:
                setattr(self, attr, p.decode_device_id_reply(reply)[1])
        settings = p.SamplingSettings(decimation=self.decimation, flags=self.flags,
                                      filter_window=self.filter_window)
        reply = self._request(p.cmd_sampling_settings(settings), p.SAMPLING_SETTINGS)
        confirmed = None if reply is None else p.decode_sampling_reply(reply)
        if confirmed is None or confirmed.decimation != self.decimation:
            self.last_error = 'sampling settings 0xDB not confirmed'
            self.log('warn', f'{self.link.port}: {self.last_error}')
            return False
        self.sampling = confirmed
        if confirmed.filter_window != self.filter_window:
            self.log('warn', f'{self.link.port}: the device filters over '
                             f'{confirmed.filter_window} samples, not the '
                             f'{self.filter_window} asked for')
        reply = self._request(p.cmd_continuous(self.code), p.SET_CONTINUOUS,
                              lambda r: r[1] == self.code)
        if reply is None:
            self.last_error = f'continuous mode 0x{self.code:02X} not confirmed'
            self.log('warn', f'{self.link.port}: {self.last_error}')
            return False
        # A new stream: its first record is not compared with the last one of the old one.
        self._new_epoch()
        self.log('info', f'{self.link.port}: {self.model or "device"} {self.serial_number} '
                         f'firmware {self.firmware} streaming 0x{self.code:02X} at '
                         f'{p.rate_for_decimation(self.decimation):g} Hz')
        return True

    def _change_baud(self):
        """Handle a device that did not answer at our baud: try 115200, switch it with 0xD9."""
        self.link.set_baud(p.DEFAULT_BAUD)
        self.link.write(p.cmd_stop_continuous())
        reply = self._request(p.cmd_comm_settings(self.baud, function=1), p.COMM_SETTINGS)
        self.link.set_baud(self.baud)
        if reply is None or p.decode_comm_reply(reply)[1] != self.baud:
            return None
        self.log('info', f'{self.link.port}: device switched from 115200 to {self.baud} baud')
        return self._request(p.cmd_firmware_version(), p.FIRMWARE_VERSION)
