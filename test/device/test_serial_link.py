"""Time sync, back-off, rate validation, CDR packing and the simulator over a real pty."""

from collections import deque
import csv
import math
import signal
import subprocess
import sys
import time

from imu_allan.device import gx3_protocol as p
from imu_allan.device.gx3_stream import StreamParser
from imu_allan.device.serial_link import Backoff, check_rate, LinkError, SerialLink, TimeSync
from imu_allan.formats.imu_cdr import header_padding
import numpy as np
import pytest
import serial

# --------------------------------------------------------------------------------- time sync


def simulate_arrivals(seconds=60.0, rate=100.0, drift=1e-4, batch=5, seed=0):
    """Device times, true host sampling times and jittered arrival times (s)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * rate)
    device = np.arange(n) / rate + 123.0
    true_host = 1_700_000_000.0 + device * (1.0 + drift)
    # Transport delay >= 0: 1 ms plus exponential jitter (mean 3 ms) plus rare 40 ms hiccups.
    delay = 1e-3 + rng.exponential(3e-3, n) + (rng.random(n) < 0.01) * 0.04
    # Records are read in batches: each one arrives with the last of its batch.
    arrival = true_host + delay
    for i in range(0, n, batch):
        arrival[i:i + batch] = arrival[min(i + batch, n) - 1]
    return device, true_host, arrival


def run_sync(sync, device, arrival, batch=5):
    """Feed the sync batch by batch; return integer-ns stamps."""
    out = [sync.stamps(device[i:i + batch], arrival[i:i + batch])
           for i in range(0, len(device), batch)]
    return np.concatenate(out)


def test_time_sync_even_spacing_and_drift():
    """
    Spacing = device spacing within the slew bound despite jitter; drift is followed.

    Tolerances: spacing error <= max_slew (5e-4) + 1 ns rounding, by construction; after
    convergence the stamp leads the true sampling time by at most the minimum delay over the
    window plus the slew lag (< 2.5 ms here), where ignoring the 1e-4 drift would be 6 ms off
    after 60 s.
    """
    device, true_host, arrival = simulate_arrivals()
    sync = TimeSync()
    stamps = run_sync(sync, device, arrival)
    spacing = np.diff(stamps) * 1e-9
    rel = spacing / np.diff(device) - 1.0
    assert np.max(np.abs(rel)) <= 5e-4 + 1e-9 / 0.01
    err = stamps * 1e-9 - true_host
    assert np.all(err[-3000:] > 0) and np.all(err[-3000:] < 2.5e-3), (err.min(), err.max())
    assert sync.jumps == 0


def test_time_sync_reanchors_on_discontinuities():
    """
    A host-clock step is taken once the minimum window has seen only the new offset.

    The device clock runs on evenly while the host clock steps 5 s forward: the old minimum
    still holds for the 10 s window, then the offset re-anchors (one jump), and a device time
    going back (reset) re-anchors at once.
    """
    device, _, arrival = simulate_arrivals(seconds=30, drift=0.0)
    sync = TimeSync()
    half = len(device) // 2
    stamps = run_sync(sync, device[:half], arrival[:half])
    later = run_sync(sync, device[half:], arrival[half:] + 5.0)
    assert sync.jumps == 1
    assert np.all(np.diff(later[:500]) > 0) and later[0] > stamps[-1]
    assert abs(later[-1] * 1e-9 - (arrival[-1] + 5.0)) < 0.05
    back = sync.stamps(device[:5], arrival[-5:] + 5.5)
    assert sync.jumps == 2 and abs(back[-1] * 1e-9 - (arrival[-1] + 5.5)) < 0.05
    sync.reset()
    again = sync.stamps(device[:5], arrival[:5] + 100.0)
    assert abs(again[0] * 1e-9 - (arrival[4] + 100.0)) < 0.05


def stamps_one_by_one(sync, device, host):
    """
    Return the stamps of one batch by the module docstring's rule, record by record in floats.

    A reference for :meth:`TimeSync.stamps`: T = the window minimum of host - device over the
    batches so far, o moves towards T by at most max_slew per second of device time since the
    last stamp, stamp = round((d + o) * 1e9) ns on a whole-second epoch.  Shares the
    TimeSync's state (window, offset) so that it can run beside it batch after batch.  Also
    returns whether the slew limit held back any record's offset.
    """
    if sync.epoch is None:
        sync.epoch = math.floor(host[0])
    if sync.last_device is not None and device[0] < sync.last_device:
        sync.reset()
        sync.jumps += 1
    batch_min = min((h - sync.epoch) - d for d, h in zip(device, host))
    minima = [m for m in sync.minima if m[1] < batch_min] + [(device[-1], batch_min)]
    minima = [m for m in minima if not m[0] < device[-1] - sync.window]
    sync.minima = deque(minima)
    target = minima[0][1]
    if sync.offset is None or abs(target - sync.offset) > sync.jump_threshold:
        sync.jumps += sync.offset is not None
        sync.offset, sync.last_device = target, device[0]
    out, limited = [], False
    for d in device:
        allowed = sync.max_slew * max(d - sync.last_device, 0.0)
        limited |= abs(target - sync.offset) > allowed
        offset = sync.offset + min(max(target - sync.offset, -allowed), allowed)
        out.append(round((d + offset) * 1e9) + sync.epoch * 10**9)
    sync.offset, sync.last_device = offset, device[-1]
    return out, limited


def test_time_sync_batches_equal_the_rule_record_by_record():
    """
    TimeSync.stamps gives, to the nanosecond, the rule evaluated per record in plain floats.

    Batches of 1..12 records with jitter (the offset slews element-wise), converged stretches
    (the scalar shortcut), a host-clock step (a jump) and a device-time reset; fixed seed,
    exact integer comparison.
    """
    device, _, arrival = simulate_arrivals(seconds=40, drift=2e-4, seed=4)
    arrival[1000:] += 0.9                  # host clock step: a jump once the window forgets
    device[3000:] -= 25.0                  # device time goes back at a batch start: a reset
    rng = np.random.default_rng(5)
    cuts = np.cumsum(rng.integers(1, 13, size=len(device)))
    cuts = np.union1d(cuts[cuts < len(device)], [3000])
    fast, ref = TimeSync(), TimeSync()
    limited = []
    for d, h in zip(np.split(device, cuts), np.split(arrival, cuts)):
        expect, held_back = stamps_one_by_one(ref, d.tolist(), h.tolist())
        got = fast.stamps(d, h)
        assert got.dtype == np.int64 and got.tolist() == expect
        assert (fast.offset, fast.last_device, fast.jumps) == (ref.offset, ref.last_device,
                                                               ref.jumps)
        limited.append(held_back)
    assert fast.jumps == 2 and 10 <= sum(limited) <= len(limited) - 10


def test_backoff():
    """0.25 s doubling to a 5 s cap; reset after success."""
    b = Backoff()
    assert [b.next() for _ in range(7)] == [0.25, 0.5, 1.0, 2.0, 4.0, 5.0, 5.0]
    b.reset()
    assert b.next() == 0.25


def test_check_rate():
    """Rates the link cannot carry are refused with a reason naming the limit."""
    assert check_rate(100, 115200, 'accel_rate') == (10, p.DEFAULT_FLAGS)
    assert check_rate(1000, 921600, 'accel_rate') == (1, p.FLAG_CONING_SCULLING)
    assert check_rate(500, 460800, 'accel_rate_orientation') == (2, p.DEFAULT_FLAGS)
    with pytest.raises(ValueError, match='at most 250 Hz; use baud 460800'):
        check_rate(500, 115200, 'accel_rate')
    with pytest.raises(ValueError, match='at most 142.9 Hz'):
        check_rate(200, 115200, 'accel_rate_mag_orientation')
    with pytest.raises(ValueError, match='500 Hz'):
        check_rate(1000, 921600, 'accel_rate_mag_orientation')
    with pytest.raises(ValueError, match='mode'):
        check_rate(100, 115200, 'euler')


def test_serial_link_errors(tmp_path):
    """A missing port is a one-line LinkError naming it."""
    link = SerialLink(str(tmp_path / 'nope'), 115200)
    with pytest.raises(LinkError, match='nope: cannot open'):
        link.open()
    assert not link.is_open


# ------------------------------------------------------------------------------ CDR packing

def same_message(expected, got):
    """
    Compare serialized messages byte for byte, but for ``expected``'s padding after the header.

    rclpy leaves that padding as it was in memory; CdrPacker zeroes it (checked here).
    """
    pad = header_padding(got)
    return (got[pad] == bytes(pad.stop - pad.start)
            and expected[:pad.start] + got[pad] + expected[pad.stop:] == got)


@pytest.mark.ros
def test_cdr_packer_matches_rclpy_serializer():
    """Patched CDR bytes deserialize to the values; identical to rclpy's own bytes."""
    pytest.importorskip('rclpy')
    from imu_allan.nodes.driver import CdrPacker
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Imu, MagneticField
    msg = Imu()
    msg.header.frame_id = 'gx3_frame'
    msg.angular_velocity_covariance = [0.5] * 9
    msg.orientation_covariance = [-1.0] + [0.0] * 8
    packer = CdrPacker(msg, {'angular_velocity': (msg.angular_velocity, 'xyz'),
                             'linear_acceleration': (msg.linear_acceleration, 'xyz'),
                             'orientation': (msg.orientation, 'xyzw')})
    rng = np.random.default_rng(1)
    gyro, accel, quat = rng.normal(size=(4, 3)), rng.normal(size=(4, 3)), rng.normal(size=(4, 4))
    stamps = np.array([0, 1_700_000_000_123_456_789, 5, 2**40], dtype=np.int64)
    secs, nsecs = stamps // 10**9, stamps % 10**9
    raw, size = packer.pack(stamps, angular_velocity=gyro, linear_acceleration=accel,
                            orientation=quat)
    for i in range(4):
        chunk = raw[i * size:(i + 1) * size]
        back = deserialize_message(chunk, Imu)
        assert back.header.stamp.sec * 10**9 + back.header.stamp.nanosec == stamps[i]
        assert back.header.frame_id == 'gx3_frame'
        assert (back.angular_velocity.x, back.angular_velocity.y, back.angular_velocity.z) \
            == tuple(gyro[i])
        assert back.linear_acceleration.z == accel[i, 2] and back.orientation.w == quat[i, 3]
        assert list(back.angular_velocity_covariance) == [0.5] * 9
        ref = Imu()
        ref.header.frame_id = 'gx3_frame'
        ref.header.stamp.sec, ref.header.stamp.nanosec = int(secs[i]), int(nsecs[i])
        ref.angular_velocity_covariance = [0.5] * 9
        ref.orientation_covariance = [-1.0] + [0.0] * 8
        ref.angular_velocity.x, ref.angular_velocity.y, ref.angular_velocity.z = gyro[i]
        ref.linear_acceleration.x, ref.linear_acceleration.y, ref.linear_acceleration.z = \
            accel[i]
        ref.orientation.x, ref.orientation.y, ref.orientation.z, ref.orientation.w = quat[i]
        assert same_message(serialize_message(ref), chunk)
    mag = MagneticField()
    mpack = CdrPacker(mag, {'magnetic_field': (mag.magnetic_field, 'xyz')})
    raw, size = mpack.pack([7 * 10**9 + 8], magnetic_field=np.array([[1e-5, 2e-5, -4e-5]]))
    back = deserialize_message(raw, MagneticField)
    assert same_message(serialize_message(back), raw)
    assert back.magnetic_field.z == -4e-5 and back.header.stamp.nanosec == 8
    assert back.header.stamp.sec == 7


def test_matrix_to_quaternion_known_rotation():
    """90 deg yaw: M (earth->sensor) = Rz(90)^T gives q = (0, 0, sin 45, cos 45)."""
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    q = p.matrix_to_quaternion(rz.T.ravel()[None])[0]
    assert q == pytest.approx([0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)], abs=1e-15)


# ------------------------------------------------------------------------- simulator on a pty

@pytest.fixture
def sim(tmp_path):
    """Start gx3_sim with extra args; yield (serial port, truth path) factory."""
    started = []

    def start(*args, baud=115200):
        truth = str(tmp_path / f'truth{len(started)}.csv')
        proc = subprocess.Popen([sys.executable, '-m', 'imu_allan.cli.gx3_sim',
                                 '--record-truth', truth, '--seed', '3'] + list(args),
                                stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
        started.append(proc)
        path = proc.stdout.readline().decode().strip()
        port = serial.Serial(path, baud, timeout=0.05)
        return proc, port, truth

    yield start
    for proc in started:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(10)


def exchange(port, command, length, timeout=2.0):
    """Send a command; return the next complete reply of ``length`` bytes."""
    port.reset_input_buffer()
    port.write(command)
    parser = StreamParser()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for packet in parser.feed(port.read(256)):
            if len(packet) == length and packet[0] == command[0] or packet[0] == p.ERROR:
                return packet
    raise AssertionError(f'no reply to {command.hex()}')


def test_sim_answers_commands(sim):
    """Identity, firmware, error reply, clamping, baud change, timer set, bias capture."""
    _, port, _ = sim()
    assert p.decode_firmware_reply(exchange(port, p.cmd_firmware_version(), 7)) == \
        (1130, '1.1.30')
    assert p.decode_device_id_reply(exchange(port, p.cmd_device_id(2), 20)) == \
        (2, '3DM-GX3-25')
    assert exchange(port, b'\xC4\x00\x00\xC2', 8) == p.ERROR_REPLY
    for asked, got in ((0, 1), (5000, 1000), (4, 4)):
        reply = exchange(port, p.cmd_sampling_settings(p.SamplingSettings(decimation=asked)),
                         19)
        assert p.decode_sampling_reply(reply).decimation == got
    assert p.decode_sampling_reply(exchange(port, p.cmd_read_sampling_settings(), 19)) \
        .decimation == 4
    assert p.decode_comm_reply(exchange(port, p.cmd_comm_settings(9600), 10))[1] == 115200
    # Baud change: the reply comes at the old rate, then only the new rate works.
    assert p.decode_comm_reply(exchange(port, p.cmd_comm_settings(921600), 10))[1] == 921600
    with pytest.raises(AssertionError, match='no reply'):
        exchange(port, p.cmd_firmware_version(), 7, timeout=0.5)
    port.baudrate = 921600
    assert p.decode_comm_reply(exchange(port, p.cmd_comm_settings(0, 0), 10))[1] == 921600
    assert p.decode_timer_reply(exchange(port, p.cmd_timer(1, 2**32 - 5), 7)) == 2**32 - 5
    reply = exchange(port, b'\xCD\xC1\x29\x27\x10', 19)
    assert p.checksum_ok(reply) and reply[0] == 0xCD
    record = p.decode_record(exchange(port, p.cmd_poll(0xCB), 43))
    assert record.fields['accel'][2] == pytest.approx(-1.0, abs=0.05)    # 1 g on -z
    assert np.linalg.norm(record.fields['mag']) == pytest.approx(0.49, abs=0.01)  # gauss


def read_truth(path):
    """Truth rows."""
    with open(path, encoding='utf-8') as stream:
        return list(csv.DictReader(line for line in stream if not line.startswith('#')))


def test_sim_faults_match_truth(sim):
    """500 Hz with corrupt, dropped and junk records: a parser's counters equal the truth."""
    proc, port, truth = sim('--corrupt-rate', '0.05', '--drop-rate', '0.05',
                            '--garbage-rate', '0.05', '--baud', '460800', baud=460800)
    port.write(p.cmd_sampling_settings(p.SamplingSettings(decimation=2))
               + p.cmd_continuous(0xC2))
    parser = StreamParser()
    packets = []
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        packets += parser.feed(port.read(4096))
    port.write(p.cmd_stop_continuous())
    # Drain until the port has been quiet for 1 s: on a loaded machine the simulator may
    # still send a record or two after the stop command (one sleep-and-read missed one, and
    # so did a 0.3 s quiet spell once in a full test run).
    quiet_since, end = time.monotonic(), time.monotonic() + 10.0
    while time.monotonic() - quiet_since < 1.0 and time.monotonic() < end:
        chunk = port.read(65536)
        if chunk:
            packets += parser.feed(chunk)
            quiet_since = time.monotonic()
    # Junk or a damaged record near the end can hold a header-like byte announcing a packet
    # longer than what follows; the records behind it come out of flush (that was a record
    # short in about one run in ten).
    packets += parser.flush()
    proc.send_signal(signal.SIGTERM)
    proc.wait(10)
    rows = read_truth(truth)
    data = [r for r in rows if r['code'] == '0xC2' and r['status'] != 'reply']
    records = [x for x in packets if x[0] == 0xC2]
    status = [r['status'] for r in data]
    assert len(records) == status.count('ok') > 500
    assert parser.stats.bad_checksums == status.count('corrupted') > 10
    assert parser.stats.resyncs == sum(r['status'] == 'garbage' for r in rows) > 10
    assert status.count('dropped') > 10
    ticks = [p.timer_of(x) for x in records]
    assert ticks == [int(r['timer']) for r in data if r['status'] == 'ok']
    gaps = np.diff(ticks)
    assert set(np.unique(gaps * 2 % 125).tolist()) == {0}     # multiples of 62.5 ticks
    lost = int(np.sum(np.round(gaps / 125.0) - 1))
    # only faults between the first and the last intact record show up as timer gaps
    first, last = status.index('ok'), len(status) - 1 - status[::-1].index('ok')
    inner = status[first:last + 1]
    assert lost == inner.count('dropped') + inner.count('corrupted')
    for x, row in zip(records[:50], [r for r in data if r['status'] == 'ok']):
        rec = p.decode_record(x)
        assert rec.fields['gyro'] == tuple(float(row[k]) for k in ('gyro_x', 'gyro_y',
                                                                   'gyro_z'))


def test_sim_power_up_streaming_and_stop(sim):
    """--stream C2 streams from power-up at --rate-hz; FA 75 B4 stops it silently."""
    _, port, _ = sim('--stream', 'C2', '--rate-hz', '200')
    parser = StreamParser()
    got = []
    end = time.monotonic() + 0.5
    while time.monotonic() < end:
        got += parser.feed(port.read(4096))
    assert len(got) > 20 and all(x[0] == 0xC2 for x in got)
    assert set(np.diff([p.timer_of(x) for x in got]).tolist()) <= {312, 313}
    port.write(p.cmd_stop_continuous())
    time.sleep(0.2)
    port.reset_input_buffer()
    time.sleep(0.2)
    assert port.read(4096) == b''


def test_sim_bad_arguments():
    """One line on stderr and exit 2; --help exits 0."""
    run = [sys.executable, '-m', 'imu_allan.cli.gx3_sim']
    out = subprocess.run(run + ['--drop-rate', '1.5'], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and out.stderr.count('\n') == 1 and '--drop-rate' in out.stderr
    out = subprocess.run(run + ['--bogus'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr.count('\n') == 1
    out = subprocess.run(run + ['--stream', 'ZZ'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and '--stream' in out.stderr
    out = subprocess.run(run + ['--help'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and '--corrupt-rate' in out.stdout


# ------------------------------------------------------------- reconnect: the parser is flushed

class _CountingParser(StreamParser):
    """A StreamParser that also sums the bytes of the packets it accepts (byte accounting)."""

    accepted = 0

    def feed(self, data):
        """Feed, and add up the accepted packets' bytes."""
        out = super().feed(data)
        self.accepted += sum(map(len, out))
        return out


def _session(port_path, batches):
    from imu_allan.device.serial_link import Gx3Session, SessionHooks, SessionOptions
    session = Gx3Session(port_path, 115200, 'accel_rate', 100.0,
                         SessionHooks(lambda code, rec, stamps: batches.append(rec.copy())),
                         SessionOptions(stall_timeout=2.0, poll_interval=0.002,
                                        backoff=Backoff(initial=0.05, maximum=0.2)))
    session.parser = _CountingParser()
    return session


def test_port_loss_flushes_the_parser_and_counts_the_false_header(tmp_path):
    """
    Bytes held behind a false header when the port closes: good records delivered, rest counted.

    A real pty carries two records, a header-like byte (0xC5: announces 43 bytes) with 10
    junk bytes, then a third record: the parser delivers the first two and holds the
    last 41 bytes (the false packet reaches past them).  The far end then closes (a
    disconnect); the session's loss path flushes as parse_bytes ends a capture: the third
    record is delivered and the 11 bytes are counted in ``rejected_bytes``.  Before, the
    reopen reset them away uncounted.
    """
    import os
    records = [p.encode_record(p.ACCEL_RATE, [0.1 * k] * 6, 1000 + 625 * k) for k in range(3)]
    false = bytes([0xC5]) + bytes(range(1, 11))
    stream = records[0] + records[1] + false + records[2]
    master, slave = os.openpty()
    batches = []
    session = _session(os.ttyname(slave), batches)
    try:
        session.link.open()
        os.write(master, stream)
        end = time.monotonic() + 5.0
        while session.link.serial.in_waiting < len(stream) and time.monotonic() < end:
            time.sleep(0.001)
        assert session._pump() == 2
        assert session.parser.buffered == len(false) + len(records[2])
        os.close(master)
        master = None
        with pytest.raises(LinkError):
            while True:
                session.link.read()
        session.backoff = Backoff(initial=0.0, maximum=0.0)
        session._lost('disconnected')
    finally:
        session.link.close()
        if master is not None:
            os.close(master)
        os.close(slave)
    ps = session.parser.stats
    assert sum(len(b) for b in batches) == 3 and session.stats.records == 3
    assert ps.rejected_bytes == len(false) and session.parser.buffered == 0
    assert ps.bytes_in == session.parser.accepted + ps.rejected_bytes


def test_simulator_disconnect_every_byte_accounted(sim, tmp_path):
    """
    The simulator closes its terminal mid-stream and comes back; nothing read goes unaccounted.

    With junk between records (header-like bytes among it), after the reconnect every byte
    the session read is in an accepted packet, in ``rejected_bytes`` or still buffered.
    """
    link = str(tmp_path / 'gx3')
    proc, port, _ = sim('--link', link, '--garbage-rate', '0.3', '--disconnect-after', '0.6',
                        '--disconnect-seconds', '0.4')
    port.close()
    batches = []
    session = _session(link, batches)
    session.start()
    try:
        end = time.monotonic() + 30.0
        while time.monotonic() < end and not (session.stats.reconnects >= 1
                                              and session.stats.records > 150):
            time.sleep(0.05)
    finally:
        session.stop()
    assert session.stats.reconnects >= 1 and session.stats.records > 150
    ps = session.parser.stats
    assert ps.rejected_bytes > 0
    assert ps.bytes_in == session.parser.accepted + ps.rejected_bytes + session.parser.buffered
