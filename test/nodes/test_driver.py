"""
End to end over real DDS: gx3_sim on a pseudo-terminal -> built driver -> rclpy subscriber.

Every published value is checked against the simulator's truth file (what it put on the wire,
float32 exact), plus units, stamp spacing, counts, covariances and /diagnostics counters, on a
clean stream and with corrupt bytes, dropped records, junk, a stall and a disconnect injected.
Nothing here asserts timing: waits have generous timeouts and end on conditions.
"""

import csv
import os
import signal
import subprocess
import time

from conftest import DOMAIN
import numpy as np
import pytest

pytestmark = pytest.mark.ros

os.environ['ROS_DOMAIN_ID'] = str(DOMAIN)
rclpy = pytest.importorskip('rclpy')

G = 9.80665
TICKS = 62500


def executable(name):
    """Path of a built executable, found like ``ros2 run`` does (ament index)."""
    from ament_index_python.packages import get_package_prefix, PackageNotFoundError
    try:
        prefix = get_package_prefix('imu_allan')
    except PackageNotFoundError:
        pytest.skip('imu_allan is not built/installed (run through make test)')
    path = os.path.join(prefix, 'lib', 'imu_allan', name)
    if not os.access(path, os.X_OK):
        pytest.skip(f'{path} missing (run through make test)')
    return path


@pytest.fixture(scope='module')
def node():
    """One rclpy node in its own context (own ROS_DOMAIN_ID, set above)."""
    from rclpy.executors import SingleThreadedExecutor
    context = rclpy.Context()
    rclpy.init(context=context)
    n = rclpy.create_node('test_driver_e2e', context=context)
    n.executor_for_test = SingleThreadedExecutor(context=context)
    n.executor_for_test.add_node(n)
    yield n
    n.executor_for_test.shutdown()
    n.destroy_node()
    rclpy.try_shutdown(context=context)


@pytest.fixture
def procs():
    """Subprocesses started by a test; all terminated at the end whatever happens."""
    started = []
    yield started
    for proc in started:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)


def read_truth(path):
    """Rows of the simulator's truth CSV as dicts (values still strings)."""
    with open(path, encoding='utf-8') as stream:
        lines = [line for line in stream if not line.startswith('#')]
    return list(csv.DictReader(lines))


def diag_values(msg):
    """Key/value dict of the driver's diagnostic status."""
    status = msg.status[0]
    out = {kv.key: kv.value for kv in status.values}
    out['_level'] = status.level
    return out


class Run:
    """gx3_sim + driver + subscriptions for one scenario."""

    def __init__(self, node, procs, tmp_path, sim_args, params, mag=False, orientation=False):
        """Start both programs and subscribe."""
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.qos import qos_profile_sensor_data, QoSProfile
        from sensor_msgs.msg import Imu, MagneticField
        self.node = node
        self.truth_path = str(tmp_path / 'truth.csv')
        self.port = str(tmp_path / 'gx3')
        env = dict(os.environ)
        # The driver starts first, on a port that does not exist yet (it retries with
        # back-off); the device appears once the test's subscriber has discovered the
        # publisher, so not even the first record can be lost to DDS discovery.
        args = [executable('driver'), '--ros-args', '-p', f'port:={self.port}']
        for key, value in params.items():
            args += ['-p', f'{key}:={value}']
        self.driver = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL,
                                       stderr=open(tmp_path / 'driver.log', 'w'))
        procs.append(self.driver)
        self.raw, self.data, self.mag, self.diags, self.received = [], [], [], [], []
        # Best effort like the publisher (sensor-data QoS), but a deep history so that a
        # slow moment in this test's executor cannot lose messages.
        qos = QoSProfile(depth=5000, reliability=qos_profile_sensor_data.reliability)
        self.subs = [
            node.create_subscription(Imu, 'imu/data_raw', self._on_raw, qos),
            node.create_subscription(DiagnosticArray, '/diagnostics', self.diags.append, 50)]
        if orientation:
            self.subs.append(node.create_subscription(Imu, 'imu/data', self.data.append, qos))
        if mag:
            self.subs.append(node.create_subscription(MagneticField, 'imu/mag',
                                                      self.mag.append, qos))
        topics = ['imu/data_raw'] + ['imu/data'] * orientation + ['imu/mag'] * mag
        self.spin_until(lambda: all(node.count_publishers(t) for t in topics), 30)
        assert all(node.count_publishers(t) for t in topics), 'driver never appeared'
        self.spin_until(lambda: False, 0.3)
        self.sim = subprocess.Popen(
            [executable('gx3_sim'), '--record-truth', self.truth_path, '--link', self.port]
            + sim_args, stdout=subprocess.PIPE, stderr=open(tmp_path / 'sim.log', 'w'),
            env=env)
        procs.append(self.sim)
        assert self.sim.stdout.readline().decode().strip() == self.port

    def _on_raw(self, msg):
        self.raw.append(msg)
        self.received.append(time.time())

    def spin_until(self, done, timeout):
        """Spin until ``done()`` or the timeout (s) passes."""
        end = time.monotonic() + timeout
        while time.monotonic() < end and not done():
            self.node.executor_for_test.spin_once(timeout_sec=0.05)
            assert self.driver.poll() is None, 'driver exited'
        for _ in range(5):
            self.node.executor_for_test.spin_once(timeout_sec=0.02)

    def last_diag(self):
        """Values of the last diagnostics message."""
        assert self.diags, 'no /diagnostics received'
        return diag_values(self.diags[-1])

    def stop(self, linger=0.5):
        """SIGINT the driver (it stops continuous mode), let the sim run on, then stop it."""
        self.driver.send_signal(signal.SIGINT)
        assert self.driver.wait(10) == 0
        # Take what is still queued in our subscriptions (published before the driver quit).
        end = time.monotonic() + linger
        while time.monotonic() < end:
            self.node.executor_for_test.spin_once(timeout_sec=0.02)
        self.sim.send_signal(signal.SIGTERM)
        self.sim.wait(10)
        for sub in self.subs:
            self.node.destroy_subscription(sub)
        return read_truth(self.truth_path)


def match(msgs, rows):
    """Positions in ``rows`` of each message, matched by the exact gyro values sent."""
    index = {}
    for pos, row in enumerate(rows):
        if row['status'] in ('ok', 'corrupted', 'dropped'):
            key = (float(row['gyro_x']), float(row['gyro_y']), float(row['gyro_z']))
            index[key] = pos
    out = []
    for msg in msgs:
        w = msg.angular_velocity
        pos = index.get((w.x, w.y, w.z))
        assert pos is not None, f'published value not sent by the simulator: {w}'
        assert rows[pos]['status'] == 'ok', f'a damaged record was published: {rows[pos]}'
        out.append(pos)
    assert out == sorted(out) and len(set(out)) == len(out), 'order changed or duplicates'
    return out


def check_values(msgs, rows, positions, gravity=G):
    """Angular rate = float32 sent; acceleration = float32 sent (g) * gravity, exactly."""
    for msg, pos in zip(msgs, positions):
        row = rows[pos]
        a = msg.linear_acceleration
        assert (a.x, a.y, a.z) == tuple(float(row[k]) * gravity
                                        for k in ('accel_x', 'accel_y', 'accel_z'))


def stamp_ns(msg):
    """Header stamp as integer nanoseconds."""
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def lost_between(rows, positions, first, last):
    """Positions of 'ok' rows in [first, last] that were not published."""
    published = set(positions)
    return [i for i in range(first, last + 1)
            if rows[i]['status'] == 'ok' and i not in published]


def count(rows, start, end, statuses):
    """Rows in positions [start, end] whose status is in ``statuses``."""
    return sum(1 for r in rows[start:end + 1] if r['status'] in statuses)


def nth_ok(rows, start, n):
    """Position of the n-th (1-based) 'ok' row from ``start``."""
    seen = 0
    for i in range(start, len(rows)):
        if rows[i]['status'] == 'ok':
            seen += 1
            if seen == n:
                return i
    return len(rows) - 1


def trailing_end(rows, pos):
    """Last position of the run of non-ok data rows right after ``pos``."""
    while pos + 1 < len(rows) and rows[pos + 1]['status'] in ('corrupted', 'dropped',
                                                              'garbage'):
        pos += 1
    return pos


def counter_bounds(rows, first, diag, statuses, gaps=False):
    """
    Bounds of a diagnostics counter from the truth rows the driver had seen.

    The counter was read when ``published`` records had been published and ``packets``
    delivered; anything between (and damaged records right after) may or may not be in it.
    """
    lo_end = nth_ok(rows, first, int(diag['published']))
    hi_end = nth_ok(rows, first, int(diag['packets']))
    if not gaps:
        hi_end = trailing_end(rows, hi_end)
    return count(rows, first, lo_end, statuses), count(rows, first, hi_end, statuses)


def set_parameters(run, values):
    """Set driver parameters one by one through its set_parameters service."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter
    client = run.node.create_client(SetParameters, '/driver/set_parameters')
    try:
        assert client.wait_for_service(timeout_sec=10)
        results = []
        for name, value in values.items():
            request = SetParameters.Request(
                parameters=[Parameter(name, value=value).to_parameter_msg()])
            future = client.call_async(request)
            run.spin_until(future.done, 10)
            results.append(future.result().results[0])
        return results
    finally:
        run.node.destroy_client(client)


# ------------------------------------------------------------------------------ no ROS needed

@pytest.mark.slow
def test_help_and_bad_arguments():
    """--help exits 0; bad arguments and refused rates: one line on stderr, exit 2."""
    for name in ('driver', 'gx3_sim'):
        out = subprocess.run([executable(name), '--help'], capture_output=True, text=True,
                             timeout=60)
        assert out.returncode == 0 and 'usage' in out.stdout
    out = subprocess.run([executable('gx3_sim'), '--gravity-axis', 'w'], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert '--gravity-axis' in out.stderr
    out = subprocess.run([executable('gx3_sim'), '--model', '/nonexistent.yaml'],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and out.stderr.startswith('gx3_sim: /nonexistent.yaml:')
    for params, words in ((['rate_hz:=1000', 'baud:=115200'], 'at most 250 Hz'),
                          (['baud:=9600'], 'baud'), (['filter_window:=33'], 'filter_window'),
                          (['mode:=accel_rate_orientation', 'rate_hz:=1000',
                            'baud:=921600'], '500 Hz'),
                          (['mode:=euler'], 'mode')):
        args = [executable('driver'), '--ros-args']
        for p in params:
            args += ['-p', p]
        out = subprocess.run(args, capture_output=True, text=True, timeout=60)
        assert out.returncode == 2, out.stderr
        assert len(out.stderr.strip().splitlines()) == 1 and words in out.stderr, out.stderr


# ------------------------------------------------------------------------------- clean stream

@pytest.mark.slow
def test_clean_stream_values_units_stamps_rollover(node, procs, tmp_path):
    """200 Hz accel+rate across a u32 timer rollover: every record, exact, evenly stamped."""
    # The timer rolls over 6 s after power-up, well inside the streaming window.
    run = Run(node, procs, tmp_path,
              ['--seed', '11', '--timer-start', str(2**32 - 6 * TICKS)],
              {'rate_hz': 200, 'angular_velocity_stddev': 0.01,
               'linear_acceleration_stddev': 0.02, 'frame_id': 'gx3'})
    run.spin_until(lambda: len(run.raw) >= 500 and run.diags
                   and int(run.last_diag()['timer_rollovers']) >= 1
                   and int(run.last_diag()['published']) >= 500, 40)
    diag = run.last_diag()
    rows = run.stop()
    msgs = run.raw
    assert len(msgs) >= 500
    pos = match(msgs, rows)
    check_values(msgs, rows, pos)
    # Nothing lost, from the first record the device streamed to the last one published.
    first_data = next(i for i, r in enumerate(rows) if r['status'] == 'ok')
    assert pos[0] == first_data
    assert lost_between(rows, pos, pos[0], pos[-1]) == []
    # Units: at rest with gravity on -z the mean acceleration is (0, 0, -9.80665) m/s^2.
    acc = np.array([(m.linear_acceleration.x, m.linear_acceleration.y,
                     m.linear_acceleration.z) for m in msgs])
    assert abs(acc[:, 2].mean() + G) < 0.01 and np.all(np.abs(acc[:, :2].mean(0)) < 0.01)
    # Stamps: spacing = device timer spacing within the 5e-4 slew bound (+ ns rounding).
    timers = np.array([int(rows[i]['timer']) for i in pos], dtype=np.int64)
    steps = np.diff(timers) % 2**32
    assert set(steps.tolist()) <= {312, 313}
    assert np.any(np.diff(timers) < 0), 'the rollover was not crossed'
    spacing = np.diff([stamp_ns(m) for m in msgs]) * 1e-9
    rel = spacing / (steps / TICKS) - 1.0
    assert np.max(np.abs(rel)) <= 5e-4 + 1e-6
    assert np.all(spacing > 0)
    # Stamps are on the host clock.  The margin only catches a wrong epoch (hours off): in a
    # full test run on 2 loaded cores the last message has arrived 1.2 s after its stamp.
    assert abs(stamp_ns(msgs[-1]) * 1e-9 - run.received[-1]) < 10.0
    m = msgs[0]
    assert m.header.frame_id == 'gx3'
    assert m.orientation_covariance[0] == -1.0
    assert list(m.angular_velocity_covariance) == pytest.approx(
        [1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4], rel=1e-12)
    assert list(m.linear_acceleration_covariance) == pytest.approx(
        [4e-4, 0, 0, 0, 4e-4, 0, 0, 0, 4e-4], rel=1e-12)
    # The device's processing, as the simulator confirmed it with 0xDB: the power-up window
    # of 15 samples at 1 kHz, decimation 5 for 200 Hz.  The data carry it: outputs one apart
    # share 10 of their 15 samples, a lag-1 correlation of 2/3 (standard error about 0.05
    # with 500 messages; tolerance 0.2).
    assert (diag['filter_window_taps'], diag['filter_window_s'], diag['decimation'],
            diag['internal_rate_hz']) == ('15', '0.015', '5', '1000')
    gyro = np.array([m.angular_velocity.x for m in msgs])
    gyro -= gyro.mean()
    assert np.dot(gyro[:-1], gyro[1:]) / np.dot(gyro, gyro) == pytest.approx(2 / 3, abs=0.2)
    # Diagnostics of a clean run.
    assert diag['_level'] == b'\x00'
    assert diag['device_model'] == '3DM-GX3-25' and diag['firmware'] == '1.1.30'
    assert diag['device_serial'] == '6223.01234'
    for key in ('checksum_failures', 'resyncs', 'rejected_bytes', 'dropped_packets',
                'stalls', 'reconnects', 'timer_resets'):
        assert diag[key] == '0', key
    assert diag['timer_rollovers'] == '1'
    # Shutdown stopped continuous mode: the sim ran 0.5 s (100 records) longer, yet it
    # logged the stop command and sent nothing after it (at most one record already due).
    # (Counting from the last published record instead failed on a loaded machine: a
    # driver a second behind leaves that second unread at shutdown.)
    stop = max(i for i, r in enumerate(rows) if r['status'] == 'event' and r['code'] == '0x02')
    assert stop > pos[-1]
    assert sum(1 for r in rows[stop + 1:] if r['status'] == 'ok') <= 1


@pytest.mark.slow
def test_mag_and_orientation_mode(node, procs, tmp_path):
    """0xCC at 100 Hz: imu/data quaternion, imu/mag in tesla, both matching imu/data_raw."""
    run = Run(node, procs, tmp_path, ['--seed', '5'],
              {'rate_hz': 100, 'mode': 'accel_rate_mag_orientation',
               'orientation_stddev': 0.1, 'magnetic_field_stddev': 1e-6, 'filter_window': 7},
              mag=True, orientation=True)
    run.spin_until(lambda: len(run.raw) >= 150 and len(run.mag) >= 150
                   and len(run.data) >= 150 and run.diags
                   and run.last_diag()['state'] == 'streaming', 30)
    # The window the driver set with 0xDB, as the device echoed it.
    diag = run.last_diag()
    assert (diag['filter_window_taps'], diag['filter_window_s'], diag['decimation']) == \
        ('7', '0.007', '10')
    # Run-time parameters: a covariance can change (validated), the port setup cannot.
    results = set_parameters(run, {'angular_velocity_stddev': 0.02, 'orientation_stddev': -1.0,
                                   'rate_hz': 50.0, 'filter_window': 9})
    assert [r.successful for r in results] == [True, False, False, False]
    assert 'orientation_stddev' in results[1].reason
    run.spin_until(lambda: run.raw[-1].angular_velocity_covariance[0] == pytest.approx(4e-4),
                   20)
    assert run.raw[-1].angular_velocity_covariance[0] == pytest.approx(4e-4)
    assert run.data[-1].orientation_covariance[0] == pytest.approx(0.01)
    rows = run.stop()
    pos = match(run.raw, rows)
    check_values(run.raw, rows, pos)
    assert lost_between(rows, pos, pos[0], pos[-1]) == []
    by_stamp = {stamp_ns(m): i for m, i in zip(run.raw, pos)}
    for msg in run.mag:
        row = rows[by_stamp[stamp_ns(msg)]]
        f = msg.magnetic_field
        assert (f.x, f.y, f.z) == tuple(float(row[k]) * 1e-4 for k in ('mag_x', 'mag_y',
                                                                       'mag_z'))
        assert 20e-6 < np.linalg.norm([f.x, f.y, f.z]) < 70e-6      # an Earth field, T
    assert list(run.mag[0].magnetic_field_covariance)[::4] == pytest.approx([1e-12] * 3)
    for msg in run.data:
        row = rows[by_stamp[stamp_ns(msg)]]
        assert float(row['m11']) == 1.0           # the simulator sends the identity
        q = msg.orientation
        assert (q.x, q.y, q.z, q.w) == (0.0, 0.0, 0.0, 1.0)
        assert msg.angular_velocity.x == float(row['gyro_x'])
        assert list(msg.orientation_covariance)[::4] == pytest.approx([0.01] * 3)


# ------------------------------------------------------------------------------------ faults

def test_corrupt_dropped_and_junk(node, procs, tmp_path):
    """
    Corrupted, dropped and junk-preceded records: every intact record is published.

    The checksum, resync and dropped-packet counters match what the simulator did.
    """
    raw_file = tmp_path / 'stream.gx3raw'
    run = Run(node, procs, tmp_path,
              ['--seed', '21', '--corrupt-rate', '0.04', '--drop-rate', '0.04',
               '--garbage-rate', '0.04'], {'rate_hz': 200, 'record_raw': str(raw_file)})
    run.spin_until(lambda: len(run.raw) >= 500 and run.diags
                   and int(run.last_diag()['published']) >= 450, 40)
    diag = run.last_diag()
    rows = run.stop()
    pos = match(run.raw, rows)
    check_values(run.raw, rows, pos)
    first = pos[0]
    assert lost_between(rows, pos, first, pos[-1]) == []
    n_bad = count(rows, first, pos[-1], ('corrupted',))
    n_drop = count(rows, first, pos[-1], ('dropped',))
    n_junk = count(rows, first, pos[-1], ('garbage',))
    assert n_bad >= 5 and n_drop >= 5 and n_junk >= 5, (n_bad, n_drop, n_junk)
    lo, hi = counter_bounds(rows, first, diag, ('corrupted',))
    assert lo <= int(diag['checksum_failures']) <= hi
    lo, hi = counter_bounds(rows, first, diag, ('garbage',))
    assert lo <= int(diag['resyncs']) <= hi
    lo, hi = counter_bounds(rows, first, diag, ('corrupted', 'dropped'), gaps=True)
    assert lo <= int(diag['dropped_packets']) <= hi
    # Junk bytes = the junk the sim wrote + the damaged records' bytes (31 each).
    junk_bytes = sum(int(r['timer']) for r in rows[first:pos[-1] + 1]
                     if r['status'] == 'garbage')
    assert int(diag['rejected_bytes']) >= junk_bytes
    # The recorded raw stream reads back (analyze --format gx3raw) to the same samples.
    from imu_allan.formats.gx3raw import read_gx3raw
    samples = read_gx3raw(str(raw_file))
    gyro = [(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z)
            for m in run.raw]
    recorded = [tuple(row) for row in samples.data[:, :3].tolist()]
    start = recorded.index(gyro[0])
    assert recorded[start:start + len(gyro)] == gyro
    assert samples.data[start, 3] == run.raw[0].linear_acceleration.x
    assert any('bad checksums' in w for w in samples.warnings)
    # Dropped records make timer gaps; the stamps keep the device spacing across them.
    timers = np.array([int(rows[i]['timer']) for i in pos], dtype=np.int64)
    spacing = np.diff([stamp_ns(m) for m in run.raw]) * 1e-9
    rel = spacing / (np.diff(timers) / TICKS) - 1.0
    assert np.max(np.abs(rel)) <= 5e-4 + 1e-6


@pytest.mark.slow
def test_stall_then_resume(node, procs, tmp_path):
    """The device goes silent for 1.5 s: the node reports a stall and resumes, nothing lost."""
    run = Run(node, procs, tmp_path,
              ['--seed', '31', '--stall-after', '1.0', '--stall-seconds', '1.5'],
              {'rate_hz': 200, 'stall_timeout': 0.3})
    run.spin_until(lambda: len(run.raw) >= 600 and run.diags
                   and int(run.last_diag()['stalls']) >= 1
                   and run.last_diag()['state'] == 'streaming', 40)
    diag = run.last_diag()
    rows = run.stop()
    pos = match(run.raw, rows)
    check_values(run.raw, rows, pos)
    assert lost_between(rows, pos, pos[0], pos[-1]) == []
    event = next(i for i, r in enumerate(rows) if r['status'] == 'event' and r['code'] == '0x00')
    assert pos[0] < event < pos[-1], 'data on both sides of the stall'
    assert int(diag['stalls']) >= 1 and diag['state'] == 'streaming'
    assert diag['dropped_packets'] == '0' and diag['checksum_failures'] == '0'
    assert all(np.diff([stamp_ns(m) for m in run.raw]) > 0)


@pytest.mark.slow
def test_disconnect_and_reconnect(node, procs, tmp_path):
    """The port vanishes for 1 s and comes back (new pty behind the same link path)."""
    run = Run(node, procs, tmp_path,
              ['--seed', '41', '--disconnect-after', '1.0', '--disconnect-seconds', '1.0'],
              {'rate_hz': 200})
    run.spin_until(lambda: run.diags and int(run.last_diag()['reconnects']) >= 1
                   and int(run.last_diag()['published']) >= 450, 40)
    diag = run.last_diag()
    rows = run.stop()
    pos = match(run.raw, rows)
    check_values(run.raw, rows, pos)
    event = next(i for i, r in enumerate(rows) if r['status'] == 'event' and r['code'] == '0x01')
    before = [i for i in pos if i < event]
    after = [i for i in pos if i > event]
    assert before and after
    # Session 1: everything up to the last read before the pty vanished; at most the few
    # records written in the last read intervals were still in the closed terminal.
    assert lost_between(rows, pos, before[0], before[-1]) == []
    assert len(lost_between(rows, pos, before[-1], event)) <= 20
    # Session 2 (a freshly powered device): from its first record on, nothing lost.
    first2 = next(i for i in range(event, len(rows)) if rows[i]['status'] == 'ok')
    assert after[0] == first2
    assert lost_between(rows, pos, first2, after[-1]) == []
    assert int(diag['reconnects']) == 1 and diag['state'] == 'streaming'
    assert diag['dropped_packets'] == '0' and diag['checksum_failures'] == '0'
    assert all(np.diff([stamp_ns(m) for m in run.raw]) > 0)


def test_baud_switch_to_reach_500_hz(node, procs, tmp_path):
    """
    The device powers up at 115200 baud; the driver asked for 460800 switches it (0xD9).

    At the wrong rate the simulator cannot read the host and sends garbage (as a UART
    would), so data only flow if the driver really switched the device and itself.
    """
    run = Run(node, procs, tmp_path, ['--seed', '51'], {'rate_hz': 500, 'baud': 460800})
    run.spin_until(lambda: len(run.raw) >= 600 and run.diags
                   and int(run.last_diag()['published']) >= 600, 40)
    diag = run.last_diag()
    rows = run.stop()
    pos = match(run.raw, rows)
    check_values(run.raw, rows, pos)
    assert lost_between(rows, pos, pos[0], pos[-1]) == []
    replies = [r['code'] for r in rows if r['status'] == 'reply']
    assert '0xD9' in replies and replies.index('0xD9') < replies.index('0xC4')
    assert diag['baud'] == '460800' and diag['rate_device_hz'] == '500'
    assert diag['dropped_packets'] == '0'
    timers = np.array([int(rows[i]['timer']) for i in pos], dtype=np.int64)
    assert set(np.diff(timers).tolist()) == {125}
