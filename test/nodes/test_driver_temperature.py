"""
Temperatures end to end over real DDS: gx3_sim (temperature ramp) -> built driver -> rclpy.

The driver polls 0xD1 between data records while streaming; the simulator answers right
after a record (with that record's timer) and logs the temperature in its truth file.
Checked: no data record lost around the polls, every published temperature equals the
simulator's value as the 12-bit code carries it, stamps match the record with the same timer.
"""

from imu_allan.device import gx3_protocol as p
from nodes.test_driver import (  # noqa: F401 - node and procs are fixtures
    diag_values,
    lost_between,
    match,
    node,
    procs,
    Run,
    stamp_ns,
)
import numpy as np
import pytest

pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_temperature_polled_between_records(node, procs, tmp_path):  # noqa: F811
    """200 Hz records, 0xD1 every 0.2 s on a 20 -> 40 deg C ramp: nothing lost, exact temps."""
    from rclpy.qos import qos_profile_sensor_data, QoSProfile
    from sensor_msgs.msg import Temperature
    temps = []
    sub = node.create_subscription(
        Temperature, 'imu/temperature', temps.append,
        QoSProfile(depth=1000, reliability=qos_profile_sensor_data.reliability))
    try:
        run = Run(node, procs, tmp_path, ['--seed', '5', '--temperature', 'ramp:20:40:6'],
                  {'rate_hz': 200, 'temperature_period': 0.2, 'frame_id': 'gx3'})
        run.spin_until(lambda: len(temps) >= 10 and len(run.raw) >= 800 and run.diags
                       and int(diag_values(run.diags[-1])['temperature_readings']) >= 10, 60)
        diag = run.last_diag()
        rows = run.stop()
    finally:
        node.destroy_subscription(sub)
    assert len(temps) >= 10
    # Data records: every one the device sent between the first and last published is there.
    pos = match(run.raw, rows)
    assert lost_between(rows, pos, pos[0], pos[-1]) == []
    assert diag['checksum_failures'] == '0' and diag['resyncs'] == '0'
    assert diag['rejected_bytes'] == '0' and diag['dropped_packets'] == '0'
    # Temperatures: the simulator's values, in order, through the 12-bit code (0.06 deg C).
    replies = [r for r in rows if r['status'] == 'reply' and r['code'] == '0xD1']
    sent = [p.counts_to_celsius(p.celsius_to_counts(float(r['temperature_c'])))
            for r in replies]
    got = [m.temperature for m in temps]
    # A best-effort subscriber may miss the first readings while discovery completes: the
    # received ones must be the sent ones from where they start (ramp steps are 0.67 deg C).
    first = int(np.argmin(np.abs(np.asarray(sent) - got[0])))
    assert got == pytest.approx(sent[first:first + len(got)], abs=1e-9)
    assert got[-1] - got[0] > 2.0, 'the ramp was not seen'
    assert all(m.variance == 0.0 and m.header.frame_id == 'gx3' for m in temps)
    # Each reply carries the timer of the record before it: same stamp as that record's
    # (within the time sync's slew over one read, far below 1 ms).
    by_timer = {int(rows[i]['timer']): msg for i, msg in zip(pos, run.raw)}
    checked = 0
    for reply, msg in zip(replies, temps):
        record = by_timer.get(int(reply['timer']))
        if record is not None:
            assert abs(stamp_ns(msg) - stamp_ns(record)) < 1e6
            checked += 1
    assert checked >= 5
    # The polls and the data records share the line: the stream rate is unchanged.
    steps = np.diff([int(rows[i]['timer']) for i in pos]) % 2**32
    assert set(steps.tolist()) <= {312, 313}


@pytest.mark.slow
def test_recorded_bag_gives_the_simulated_slope(node, procs, tmp_path):  # noqa: F811
    """
    gx3_sim (20 -> 40 deg C over 30 s, gyro slopes 5e-4, -3e-4, 0 rad/s/K) -> driver -> a bag.

    The test records imu/data_raw and imu/temperature as they arrive and writes them with
    rosbags (MCAP); the built ``analyze --out`` must find each gyro slope within 1e-4 rad/s/K
    (a fifth of the largest slope) and the range up to 40 deg C.  This is the path end to end;
    the slope interval's calibration is tested in memory (test/core/test_temperature.py, also on
    36-s records like this one).  Simulator seeds 8, 3 and 11 gave normalised errors of -1.1,
    -2.6, -0.4; -2.4, 0.0, below -3; -1.6, -1.5, -0.2 with the BIC-selected noise model behind
    the interval, -0.4, -2.6, -0.4; -2.4, 0.0, n/a; -0.5, -1.5, -0.2 with every term fitted (the
    cause, in core.temperature); the same seeds' noise source without ROS gives the same
    errors, so they are these realisations (over 120 seeds: rms 1.0, no bias), not the path.
    (Those were the noise source before issue 29; the continuous one through the device's
    window gives seed 8 errors of -0.1, -0.5, -0.7.)
    """
    import json
    import subprocess

    from imu_allan.formats.bag_writer import write_imu_bag
    from imu_allan.formats.samples import Samples
    from nodes.test_driver import executable
    from rclpy.qos import qos_profile_sensor_data, QoSProfile
    from rosbags.typesys import get_typestore, Stores
    from sensor_msgs.msg import Temperature
    temps = []
    sub = node.create_subscription(
        Temperature, 'imu/temperature', temps.append,
        QoSProfile(depth=1000, reliability=qos_profile_sensor_data.reliability))
    try:
        # the driver's default window (15 taps at decimation 10): the noise model behind the
        # slope's interval is fitted knowing the filter it puts on the samples
        run = Run(node, procs, tmp_path, ['--seed', '8', '--temperature', 'ramp:20:40:30',
                                          '--temperature-slope', '5e-4,-3e-4,0'],
                  {'rate_hz': 100, 'temperature_period': 0.5})
        run.spin_until(lambda: len(run.raw) >= 3600 and len(temps) >= 72, 90)
        run.stop()
    finally:
        node.destroy_subscription(sub)
    msgs = run.raw
    t = np.array([stamp_ns(m) for m in msgs]) * 1e-9
    data = np.array([(m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z,
                      m.linear_acceleration.x, m.linear_acceleration.y,
                      m.linear_acceleration.z) for m in msgs])
    ts = get_typestore(Stores.ROS2_JAZZY)
    temp_t, header, time_t = (ts.types['sensor_msgs/msg/Temperature'],
                              ts.types['std_msgs/msg/Header'],
                              ts.types['builtin_interfaces/msg/Time'])
    recorded = []
    for m in temps:
        ns = stamp_ns(m)
        head = header(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9),
                      frame_id=m.header.frame_id)
        recorded.append((ns, temp_t(header=head, temperature=m.temperature,
                                    variance=m.variance)))
    bag = tmp_path / 'recorded'
    write_imu_bag(bag, Samples(t=t, data=data), topic='/imu/data_raw', extra_topics={
        '/imu/temperature': ('sensor_msgs/msg/Temperature', recorded)})
    out = tmp_path / 'report'
    # --allow-jumps: on a loaded machine a best-effort subscriber may miss a run of messages;
    # that is no fault of the driver, and the slope needs no unbroken record.
    proc = subprocess.run([executable('analyze'), str(bag), '--out', str(out), '--quiet',
                           '--allow-jumps'],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    section = json.loads((out / 'report.json').read_text())['temperature']
    assert section['topic'] == '/imu/temperature'
    lo, hi = section['range_c']
    # The readings inside the record: the first one follows the driver's set-up (1-5 s into
    # the 0.67 deg C/s ramp on a loaded machine), so the range is checked against what was
    # recorded, and the ramp must span most of its 20 deg C.
    celsius = [m.temperature for m in temps]
    assert min(celsius) - 1e-9 <= lo < hi <= max(celsius) + 1e-9
    assert hi - lo > 14.0 and hi > 39.0
    for axis, truth in (('gyro_x', 5e-4), ('gyro_y', -3e-4), ('gyro_z', 0.0)):
        s = section['slopes'][axis]
        assert abs(s['value'] - truth) < 1e-4, (axis, s)
        assert s['stderr'] < 1e-4       # the slopes are resolved, not just bracketed
    (move,) = section['changes']          # the ramp, as one move, from the first reading recorded
    assert move['from_c'] < lo + 3.0 and move['to_c'] > 39.0
    assert 'temperature' in proc.stdout
