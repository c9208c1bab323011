"""
``discrepancy RECORDING... --model MODEL`` (built executable): several recordings, findings.

Recordings are written here from the simulators re-implemented in ``core/simulator_pairs``:
rosbag2 bags (MCAP, written message by message with rosbags' own serializer, covariance
diagonals as the PX4 plugin fills them: NoiseDensity^2) and CSV files of gz-sensors' per-sample
white noise at 100, 250 and 1000 Hz, with the simulators' files as ``--model``.
"""

import json
import math

from conftest import run_command
from core import simulator_pairs as sp
from imu_allan.core.units import AXES
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.imu_covariance import read_covariance
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

RATES = (100.0, 250.0, 1000.0)
PX4_SDF = """<plugin name="rotors_gazebo_imu_plugin" filename="libgazebo_imu_plugin.so">
  <robotNamespace/>
  <linkName>/imu_link</linkName>
  <gyroscopeNoiseDensity>0.00018665</gyroscopeNoiseDensity>
  <gyroscopeRandomWalk>3.8785e-05</gyroscopeRandomWalk>
  <gyroscopeBiasCorrelationTime>1000.0</gyroscopeBiasCorrelationTime>
  <gyroscopeTurnOnBiasSigma>0.0087</gyroscopeTurnOnBiasSigma>
  <accelerometerNoiseDensity>0.00186</accelerometerNoiseDensity>
  <accelerometerRandomWalk>0.006</accelerometerRandomWalk>
  <accelerometerBiasCorrelationTime>300.0</accelerometerBiasCorrelationTime>
  <accelerometerTurnOnBiasSigma>0.196</accelerometerTurnOnBiasSigma>
</plugin>
"""
#: A gz sensor with an ADIS16448-like density typed into the per-sample stddev (0.66 deg/sqrt(h)).
GZ_STDDEV = 1.92e-4
GZ_SDF = f"""<sensor name="imu" type="imu"><update_rate>250</update_rate><imu>
<angular_velocity>
<x><noise type="gaussian"><stddev>{GZ_STDDEV}</stddev></noise></x>
<y><noise type="gaussian"><stddev>{GZ_STDDEV}</stddev></noise></y>
</angular_velocity></imu></sensor>
"""


def write_bag(path, t, data, covariance):
    """Write a rosbag2 (MCAP): one Imu per sample, each with the covariance diagonals given."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.ROS2_JAZZY)
    Imu = store.types['sensor_msgs/msg/Imu']
    Header = store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    Vector3 = store.types['geometry_msgs/msg/Vector3']
    Quaternion = store.types['geometry_msgs/msg/Quaternion']
    cov_w = np.diag([covariance.get(a, 0.0) for a in AXES[:3]]).reshape(9)
    cov_a = np.diag([covariance.get(a, 0.0) for a in AXES[3:]]).reshape(9)
    orient = np.zeros(9)
    orient[0] = -1.0
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/imu/data_raw', 'sensor_msgs/msg/Imu', typestore=store)
        for ti, row in zip(t, data):
            ns = int(round(ti * 1e9))
            msg = Imu(Header(Time(ns // 10**9, ns % 10**9), 'imu_link'),
                      Quaternion(0.0, 0.0, 0.0, 1.0), orient,
                      Vector3(*row[:3]), cov_w, Vector3(*row[3:]), cov_a)
            writer.write(conn, ns, store.serialize_cdr(msg, 'sensor_msgs/msg/Imu'))


@pytest.fixture(scope='module')
def px4_bags(tmp_path_factory):
    """Three 2-min bags of the PX4 plugin (iris defaults), covariance = NoiseDensity^2."""
    folder = tmp_path_factory.mktemp('px4')
    paths = []
    for k, rate in enumerate(RATES):
        n = int(120 * rate)
        data = sp.px4_run(AXES, n, rate, [7, k])
        path = folder / f'px4_{int(rate)}'
        write_bag(path, 1000.0 + np.arange(n) / rate, data, sp.px4_covariance(AXES, rate))
        paths.append(path)
    sdf = folder / 'iris_imu.sdf'
    sdf.write_text(PX4_SDF)
    return paths, sdf


@pytest.fixture(scope='module')
def gz_csvs(tmp_path_factory):
    """Three 5-min CSV recordings of gz-sensors' per-sample stddev, and the SDF."""
    folder = tmp_path_factory.mktemp('gz')
    paths = []
    for k, rate in enumerate(RATES):
        n = int(300 * rate)
        data = sp.gz_run(('gyro_x', 'gyro_y'), n, rate, [11, k],
                         config={'gyro': {'stddev': GZ_STDDEV}})
        path = folder / f'gz_{int(rate)}.csv'
        write_csv(path, Samples(np.arange(n) / rate, data, ('gyro_x', 'gyro_y'), 'gz'))
        paths.append(path)
    sdf = folder / 'robot.sdf'
    sdf.write_text(GZ_SDF)
    return paths, sdf


def test_bag_covariance_is_read_as_stated(px4_bags):
    paths, _ = px4_bags
    stated, notes = read_covariance(paths[1], '/imu/data_raw')
    assert stated == pytest.approx(sp.px4_covariance(AXES, 250.0))
    assert notes == []


def test_px4_covariance_is_a_density(px4_bags):
    """
    The PX4 plugin's covariance is NoiseDensity^2: stated / measured = (f / 1 Hz)^-1.

    Everything else is as documented (RandomWalk a driving density): the metadata findings,
    one per axis, are the only ones.
    """
    paths, sdf = px4_bags
    proc = run_command('discrepancy', *paths, '--model', sdf, '--json', timeout=600)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report['consistent'] is False
    assert {f['class'] for f in report['findings']} == {'metadata'}
    assert sorted(f['axis'] for f in report['findings']) == sorted(AXES)
    for f in report['findings']:
        lo, hi = f['rate_exponent_ci']
        assert lo - 3 * (hi - lo) < -1.0 < hi + 3 * (hi - lo)  # -1 within 3 x the 68 % width
        assert f['factor_ci95'][0] < 1.0 < f['factor_ci95'][1]
        assert 'covariance' in f['sentence'] and 'N^2 f' in f['sentence']
    assert [r['sample_rate_hz'] for r in report['recordings']] == pytest.approx(list(RATES))


def test_gz_stddev_per_sample_suggests_the_corrected_value(gz_csvs, tmp_path):
    paths, sdf = gz_csvs
    out = tmp_path / 'out'
    proc = run_command('discrepancy', *paths, '--model', sdf, '--out', out, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert 'gz <stddev> is per sample: set it to N x sqrt(250)' in proc.stdout
    report = json.loads((out / 'report.json').read_text())
    white = [f for f in report['findings'] if f['class'] == 'white_scale']
    assert sorted(f['axis'] for f in white) == ['gyro_x', 'gyro_y']
    for f in white:
        assert f['parameter'].endswith('/noise/stddev')
        assert f['suggested'] == pytest.approx(GZ_STDDEV * math.sqrt(250.0), rel=0.03)
        assert f['rate_exponent'] == pytest.approx(-0.5, abs=0.02)
    page = (out / 'report.html').read_text()
    assert 'Findings' in page and 'for the density you meant' in page
    assert not [p for p in tmp_path.iterdir() if p.name.startswith('.out')]  # staging gone


def test_correct_gz_reading_is_consistent_in_one_recording(gz_csvs, tmp_path):
    """One recording with a model file that states what was simulated: no finding."""
    paths, _ = gz_csvs
    model = tmp_path / 'model.yaml'
    model.write_text(f'gyro:\n  white_noise: {GZ_STDDEV / math.sqrt(100.0)}\n')
    proc = run_command('discrepancy', paths[0], '--model', model, '--json', '--sims', '1',
                       timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report['consistent'] is True and report['findings'] == []
    assert report['steps'] == []


def test_an_unreadable_recording_is_left_out_and_said(gz_csvs, tmp_path):
    """The others are compared; the bad one is one stderr line and a note; exit status 2."""
    paths, sdf = gz_csvs
    missing = tmp_path / 'nope.csv'
    proc = run_command('discrepancy', paths[0], missing, paths[2], '--model', sdf, '--json',
                       timeout=300)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and str(missing) in lines[0] and 'no such file' in lines[0]
    report = json.loads(proc.stdout)
    assert len(report['recordings']) == 2
    assert any(str(missing) in n for n in report['notes'])


def test_rms_density_and_zeroed_walks_name_the_keys_to_set(px4_bags, tmp_path):
    """
    Name the zeroed accelerometer walk of a block with per-sample RMS densities (issue 37).

    The iris recordings against that block (densities the per-sample RMS at 200 Hz, the
    accelerometer's RandomWalk and TurnOnBiasSigma set to 0).  On the accel axes the zeroed
    Gauss-Markov is named (``zeroed_term``, factor 1 / sqrt(200) in its 95 % interval) with
    accelerometerRandomWalk to set (the true 0.006 within a factor 1.5: a 2-min walk's fit)
    and NoiseDensity beside it; every finding is material and the report states the band.
    """
    paths, _ = px4_bags
    sdf = tmp_path / 'rms.sdf'
    sdf.write_text(PX4_SDF.replace('0.00018665', f'{0.00018665 * math.sqrt(200):.6g}')
                   .replace('0.00186', f'{0.00186 * math.sqrt(200):.6g}')
                   .replace('<accelerometerRandomWalk>0.006', '<accelerometerRandomWalk>0')
                   .replace('<accelerometerTurnOnBiasSigma>0.196',
                            '<accelerometerTurnOnBiasSigma>0'))
    proc = run_command('discrepancy', *paths, '--model', sdf, '--json', timeout=600)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report['materiality']['scale'] == [0.8, 1.25]
    assert all(f['material'] for f in report['findings'])
    zeroed = [f for f in report['findings'] if f['class'] == 'zeroed_term']
    assert sorted(f['axis'] for f in zeroed) == ['accel_x', 'accel_y', 'accel_z']
    for f in zeroed:
        assert f['factor_ci95'][0] < 200 ** -0.5 < f['factor_ci95'][1]
        assert f['parameter'] == 'accelerometerRandomWalk'
        assert 1 / 1.5 < f['suggested'] / 0.006 < 1.5
        assert f['evidence']['also']['accelerometerNoiseDensity'] == pytest.approx(0.00186,
                                                                                   rel=0.05)
        assert 'set accelerometerRandomWalk to' in f['sentence']


@pytest.mark.parametrize('args, needle', [
    (['{a}', '{b}'], 'give --model'),
    (['{a}', '{b}', '--model', '{sdf}', '--materiality', '1.1,2'], '--materiality'),
    (['{a}', '{b}', '--model', '{sdf}', '--materiality', 'wide'], '--materiality'),
    (['{missing}', '{missing}', '--model', '{sdf}'], 'no such file'),
    (['{a}', '{b}', '--model', '{sdf}', '--out', '{a}'], 'not a folder'),
    (['{a}', '{b}', '--model', '{bad}'], 'bad.sdf'),
])
def test_bad_input_is_one_line_and_status_2(gz_csvs, tmp_path, args, needle):
    paths, sdf = gz_csvs
    bad = tmp_path / 'bad.sdf'
    bad.write_text('<imu><angular_velocity><x><noise type="gaussian"><stddev>-1</stddev>'
                   '</noise></x></angular_velocity></imu>')
    names = {'a': paths[0], 'b': paths[1], 'missing': tmp_path / 'nope.csv', 'sdf': sdf,
             'bad': bad}
    proc = run_command('discrepancy', *[a.format(**names) for a in args], timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], proc.stderr
    assert 'Traceback' not in proc.stderr and proc.stdout == ''
