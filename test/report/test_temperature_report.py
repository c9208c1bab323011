"""analyze on a bag with Imu + sensor_msgs/Temperature: slopes, range, moves, coincidences."""

from types import SimpleNamespace

from imu_allan.cli.analyze import _options, build_parser, run_one
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.record import COINCIDENCE_MARGIN, coincidences
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.temperature import TemperatureChange, TemperatureProfile
from imu_allan.core.units import AXES
from imu_allan.device import gx3_protocol as p
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
from imu_allan.formats.temperature_bag import choose_temperature_topic, read_temperature
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

RATE = 100.0
SLOPES = np.array([2e-4, -1e-4, 5e-5, 2e-3, -1e-3, 5e-4])   # rad/s/K, m/s^2/K
T0 = 1_700_000_000.0                                        # stamps on a wall clock


def recording(seconds=1200.0, seed=4, profile='warmup:20:40:200'):
    """Imu samples with bias = SLOPES * (T - 20) and the 1 Hz temperatures as coded (0xD1)."""
    n = int(seconds * RATE)
    t = T0 + np.arange(n) / RATE
    prof = TemperatureProfile.parse(profile)
    data = simulate(thesis_gx3_25_model(), n, RATE, seed=seed)
    data += np.outer(prof.at(t - T0) - prof.start, SLOPES)
    temp_t = T0 + np.arange(0.0, seconds, 1.0)
    temp_c = p.counts_to_celsius(p.celsius_to_counts(prof.at(temp_t - T0)))
    return Samples(t=t, data=data), temp_t, temp_c


def temperature_messages(temp_t, temp_c, ros1=False):
    """(stamp ns, sensor_msgs/Temperature) pairs built with the rosbags typestore."""
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_JAZZY)
    temp, header, time = (ts.types['sensor_msgs/msg/Temperature'],
                          ts.types['std_msgs/msg/Header'],
                          ts.types['builtin_interfaces/msg/Time'])
    out = []
    for i, (t, c) in enumerate(zip(temp_t, temp_c)):
        ns = int(round(t * 1e9))
        sec, nsec = divmod(ns, 10**9)
        kw = {'seq': i} if ros1 else {}
        out.append((ns, temp(header=header(stamp=time(sec=sec, nanosec=nsec), frame_id='imu',
                                           **kw), temperature=float(c), variance=0.0)))
    return out


def analyze(path):
    """run_one of the analyze command on one input, --json."""
    args = build_parser().parse_args([str(path), '--json', '--quiet'])
    return run_one(str(path), args, _options(args))


@pytest.mark.parametrize('storage', ['mcap', 'ros1'])
def test_slopes_found_within_their_intervals(tmp_path, storage):
    """
    A 20 min warm-up 20 -> 40 deg C with known slopes on all six axes (fixed seed).

    Pass: every estimate within 3 standard errors of the truth (a 99.7 % band for a normal
    error; the 68.3 % interval is checked for calibration in test/core/test_temperature.py).
    """
    samples, temp_t, temp_c = recording()
    path = tmp_path / ('rec.bag' if storage == 'ros1' else 'rec')
    write_imu_bag(path, samples, topic='/imu/data_raw', storage=storage, extra_topics={
        '/imu/temperature': ('sensor_msgs/msg/Temperature',
                             temperature_messages(temp_t, temp_c, storage == 'ros1'))})
    topic, t, c = read_temperature(path, '/imu/data_raw')
    assert topic == '/imu/temperature' and np.array_equal(t, temp_t)
    assert np.array_equal(c, temp_c)
    report, text = analyze(path)
    section = report['temperature']
    assert section['topic'] == '/imu/temperature' and section['n_readings'] == temp_t.size
    assert section['range_c'] == [pytest.approx(temp_c.min()), pytest.approx(temp_c.max())]
    assert set(section['slopes']) == set(AXES)
    for j, axis in enumerate(AXES):
        s = section['slopes'][axis]
        assert abs(s['value'] - SLOPES[j]) < 3 * s['stderr'], (axis, s)
        assert s['ci'][0] < s['value'] < s['ci'][1]
        assert s['unit'] == ('rad/s/K' if axis.startswith('gyro') else 'm/s^2/K')
    # The one move: 10-90 % of the warm-up, times from the first IMU sample.
    (move,) = section['changes']
    assert move['from_c'] == pytest.approx(20.0, abs=1.5)     # a 60 s mean at the start
    assert move['to_c'] == pytest.approx(40.0, abs=0.1)
    # (later by up to the 30 s half-width of the smoothing: test/core/test_temperature.py)
    assert 200 * np.log(10 / 9) - 2 <= move['t_start_s'] <= 200 * np.log(10 / 9) + 30
    assert 200 * np.log(10) - 8 <= move['t_end_s'] <= 200 * np.log(10) + 30
    assert 'bias slope' in text and 'gyro_x' in text


def test_the_input_is_read_once_with_its_temperatures(tmp_path, monkeypatch):
    """
    Analyze reads a bag once: the Imu and the Temperature topic in the one read_samples call.

    Counted: read_samples and read_temperature one call each, and the section is the one
    computed from what that call delivered (Samples.temperature).
    """
    from imu_allan.formats import readers, temperature_bag
    samples, temp_t, temp_c = recording(seconds=300.0)
    path = tmp_path / 'rec'
    write_imu_bag(path, samples, topic='/imu/data_raw', storage='mcap', extra_topics={
        '/imu/temperature': ('sensor_msgs/msg/Temperature',
                             temperature_messages(temp_t, temp_c))})
    calls = {'read_samples': [], 'read_temperature': []}

    def counted(module, name):
        real = getattr(module, name)

        def wrapper(*args, **kwargs):
            out = real(*args, **kwargs)
            calls[name].append(out)
            return out
        monkeypatch.setattr(module, name, wrapper)
    counted(readers, 'read_samples')
    counted(temperature_bag, 'read_temperature')
    report, _ = analyze(path)
    assert len(calls['read_samples']) == 1 and len(calls['read_temperature']) == 1
    delivered = calls['read_samples'][0].temperature
    assert delivered is calls['read_temperature'][0]
    assert np.array_equal(delivered.t, temp_t) and np.array_equal(delivered.celsius, temp_c)
    assert report['temperature']['n_readings'] == temp_t.size


def test_no_temperature_topic_no_section(tmp_path):
    """An Imu-only bag and a CSV: no temperature key, nothing else changes."""
    samples, _, _ = recording(seconds=120.0)
    path = tmp_path / 'plain'
    write_imu_bag(path, samples, topic='/imu/data_raw', storage='mcap')
    assert read_temperature(path) is None
    report, _ = analyze(path)
    assert 'temperature' not in report


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_reader_lists_the_topics_and_the_bag_is_opened_again_only_for_a_temperature(
        tmp_path, storage):
    """
    The direct readers list every topic's type; read_temperature opens the bag only then.

    A 2-min bag with a Temperature topic: the listed types name it and the temperatures read
    with the list are those read without.  Without a Temperature type in the list the bag is
    not opened (a path that does not exist gives None, not the reader's InputError).
    """
    from imu_allan.errors import InputError
    from imu_allan.formats.readers import read_samples
    samples, temp_t, temp_c = recording(seconds=120.0)
    path = tmp_path / 'rec'
    write_imu_bag(path, samples, topic='/imu/data_raw', storage=storage, extra_topics={
        '/imu/temperature': ('sensor_msgs/msg/Temperature',
                             temperature_messages(temp_t, temp_c))})
    types = read_samples(path).topic_types
    assert types == {'/imu/data_raw': 'sensor_msgs/msg/Imu',
                     '/imu/temperature': 'sensor_msgs/msg/Temperature'}
    with_list = read_temperature(path, '/imu/data_raw', topic_types=types)
    without = read_temperature(path, '/imu/data_raw')
    assert with_list[0] == without[0] == '/imu/temperature'
    assert np.array_equal(with_list[1], temp_t) and np.array_equal(with_list[2], temp_c)
    imu_only = {'/imu/data_raw': 'sensor_msgs/msg/Imu'}
    missing = tmp_path / 'no_such_bag'
    assert read_temperature(missing, topic_types=imu_only) is None
    with pytest.raises(InputError):
        read_temperature(missing, topic_types=types)


def test_topic_choice_and_coincidences():
    """Several Temperature topics: the Imu's namespace wins; events related to moves."""
    assert choose_temperature_topic({'/a/temp', '/imu/temperature'}, '/imu/data_raw') == \
        '/imu/temperature'
    assert choose_temperature_topic({'/b/t', '/a/t'}, '/imu/data_raw') == '/a/t'
    assert choose_temperature_topic(set(), '/imu/data_raw') is None
    changes = [SimpleNamespace(axis='gyro_x', t_s=300.0),
               SimpleNamespace(axis='gyro_y', t_s=900.0),
               SimpleNamespace(axis='gyro_z', t_s=float('nan'))]  # no time: not related
    moves = [TemperatureChange(t_start_s=100.0, t_end_s=320.0, from_c=20.0, to_c=30.0)]
    got = [c.to_json() for c in coincidences(changes, 120.0, moves,
                                             COINCIDENCE_MARGIN * 1000.0)]
    assert [g['temperature_change'] for g in got] == [0, None, 0]
    assert got[2]['event'] == 'warmup' and got[0]['axis'] == 'gyro_x'
    assert list(got[0]) == ['event', 't_s', 'axis', 'temperature_change']  # report.json keys
    # the margin widens the move: 330 s is 10 s past its end, inside 5 % of 1000 s, not of 100
    late = [SimpleNamespace(axis='gyro_x', t_s=330.0)]
    assert coincidences(late, 0.0, moves, COINCIDENCE_MARGIN * 1000.0)[0].temperature_change == 0
    assert coincidences(late, 0.0, moves, COINCIDENCE_MARGIN * 100.0)[0].temperature_change \
        is None


@pytest.mark.slow
def test_slopes_use_the_warm_up_the_estimate_leaves_out(tmp_path):
    """
    A warm-up the Allan estimate leaves out (verdict.warmup_s > 0) still feeds the slopes.

    1 h at 100 Hz, the bias following a 20 -> 40 deg C warm-up (time constant 300 s) at five
    times SLOPES, large enough for core/checks/warmup.py to call it one.  The settling is where the
    temperature moves, so the slopes are regressed on every sample read: each within 3 of its
    standard errors of the truth (a 99.7 % band for a normal error).
    """
    profile = 'warmup:20:40:300'
    samples, temp_t, temp_c = recording(seconds=3600.0, seed=5, profile=profile)
    prof = TemperatureProfile.parse(profile)
    samples.data += 4.0 * np.outer(prof.at(samples.t - T0) - prof.start, SLOPES)
    path = tmp_path / 'warm'
    write_imu_bag(path, samples, topic='/imu/data_raw', storage='mcap', extra_topics={
        '/imu/temperature': ('sensor_msgs/msg/Temperature',
                             temperature_messages(temp_t, temp_c))})
    report, _ = analyze(path)
    assert report['verdict']['warmup_s'] > 0
    for j, axis in enumerate(AXES):
        s = report['temperature']['slopes'][axis]
        assert abs(s['value'] - 5.0 * SLOPES[j]) < 3 * s['stderr'], (axis, s)
