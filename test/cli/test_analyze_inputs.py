"""
``analyze`` on every input kind.

Real bags, a four-format round trip, several inputs, exported samples, denoising into a new
bag, and bad bags (one line, exit 2, no partial output).
"""

import json
import math

from conftest import run_command
from imu_allan import NoiseModel, simulate
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros

# Static 6-axis model, 40 min at 100 Hz: long enough for white noise and bias instability.
MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.8e-4, 'bias_instability': 1.5e-4},
                              'accel': {'white_noise': 8.3e-4, 'bias_instability': 7e-4}})
N = 100 * 2400


def _json(*args):
    proc = run_command('analyze', *args, '--json')
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.fixture(scope='module')
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp('rec')
    data = simulate(MODEL, N, 100.0, seed=404)
    data[:, 5] += 9.80665
    samples = Samples(t=1.7e9 + np.arange(N) / 100.0, data=data)
    paths = {'mcap': root / 'rec_mcap', 'sqlite3': root / 'rec_sqlite3',
             'ros1': root / 'rec.bag', 'csv': root / 'rec.csv'}
    for storage in ('mcap', 'sqlite3', 'ros1'):
        write_imu_bag(paths[storage], samples, storage=storage)
    write_csv(paths['csv'], samples)
    return paths


@pytest.mark.slow
def test_same_report_from_mcap_sqlite3_ros1_and_csv(recordings):
    reports = {k: _json(p) for k, p in recordings.items()}
    ref = reports['csv']
    for kind, rep in reports.items():
        assert rep['n_samples'] == N, kind
        for axis in MODEL.axes:
            # bag stamps are whole nanoseconds, CSV stamps exact: same samples, same estimates
            np.testing.assert_allclose(rep['axes'][axis]['adev']['adev'],
                                       ref['axes'][axis]['adev']['adev'], rtol=1e-9)
            assert rep['axes'][axis]['terms'].keys() == ref['axes'][axis]['terms'].keys()
    for axis in MODEL.axes:  # and the coefficients are found
        terms = ref['axes'][axis]['terms']
        assert terms['white_noise']['value'] == pytest.approx(
            MODEL.value(axis, 'white_noise'), rel=0.03)
        b = terms['bias_instability']
        half = (b['ci'][1] - b['ci'][0]) / 2
        assert abs(b['value'] - MODEL.value(axis, 'bias_instability')) < 3 * half, axis


@pytest.mark.slow
def test_real_bags_three_forms_agree_and_robot_was_moving(shared_data):
    bags = shared_data / 'bags'
    reports = [_json(bags / 'test2.bag'), _json(bags / 'jackal_test2_sqlite3'),
               _json(bags / 'jackal_test2_mcap')]
    for rep in reports:
        assert rep['n_samples'] == 3061
        assert rep['sample_rate_hz'] == pytest.approx(50.0, rel=0.02)
        assert rep['verdict']['static'] is False  # a driving Jackal is no Allan reference
        assert any('not static' in w for w in rep['verdict']['warnings'])
        np.testing.assert_allclose(rep['axes']['gyro_z']['adev']['adev'],
                                   reports[0]['axes']['gyro_z']['adev']['adev'], rtol=1e-12)
    husky = _json(bags / 'test1.bag', '--allow-jumps')
    assert husky['n_samples'] == 11865 and husky['verdict']['static'] is False


@pytest.mark.slow
def test_several_inputs_in_parallel_with_one_summary(recordings, tmp_path):
    bad = tmp_path / 'broken.mcap'
    bad.write_bytes(b'\x89MCAP0\r\n' + b'\x00' * 50)
    proc = run_command('analyze', recordings['mcap'], recordings['csv'], bad, '--quiet')
    assert proc.returncode == 2  # one input failed: reported, the others still analysed
    assert 'summary:' in proc.stdout
    assert str(recordings['mcap'])[-30:] in proc.stdout and 'error:' in proc.stdout
    assert len([ln for ln in proc.stderr.splitlines() if 'broken.mcap' in ln]) == 1
    proc = run_command('analyze', recordings['mcap'], recordings['sqlite3'], '--json')
    out = json.loads(proc.stdout)
    assert proc.returncode == 0 and len(out['reports']) == 2 and out['errors'] == []


@pytest.mark.slow
def test_export_samples_round_trip(recordings, tmp_path):
    exported = tmp_path / 'samples.csv'
    first = _json(recordings['ros1'], '--export-samples', exported)
    header = exported.read_text().splitlines()[0]
    assert header == 't,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z'
    again = _json(exported)
    np.testing.assert_allclose(again['axes']['accel_z']['adev']['adev'],
                               first['axes']['accel_z']['adev']['adev'], rtol=1e-12)


@pytest.mark.slow
def test_denoise_writes_a_bag_with_the_denoised_topic(recordings, tmp_path):
    from rosbags.highlevel import AnyReader
    out = tmp_path / 'den'
    proc = run_command('analyze', recordings['mcap'], '--denoise', '--out', out, '--quiet')
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / 'report.json').read_text())
    raw_n = report['axes']['gyro_x']['terms']['white_noise']['value']
    den_terms = report['denoised']['gyro_x']['terms']
    assert den_terms.get('white_noise', {'value': 0.0})['value'] < raw_n / 10
    with AnyReader([out / 'denoised_bag']) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
    assert topics['/imu/data_raw'] == N and topics['imu/data_denoised'] == N
    assert {'adev_gyro.png', 'denoised_bag', 'report.json'} <= {p.name for p in out.iterdir()}


def _samples(n=3000, rate=100.0, seed=0):
    data = np.random.default_rng(seed).normal(0, 1e-3, (n, 6))
    return Samples(t=1.7e9 + np.arange(n) / rate, data=data)


def _bad_bag(tmp_path, kind):
    path = tmp_path / f'{kind}_bag'
    s = _samples()
    if kind == 'nan':
        s.data[100, 2] = np.nan
    elif kind == 'inf':
        s.data[7, 4] = np.inf
    elif kind == 'backwards':
        s.t[500:] -= 2.0
    elif kind == 'jump':
        s.t[1500:] += 3600.0
    elif kind == 'short':
        s = _samples(n=12)
    if kind == 'empty_topic':
        write_imu_bag(path, s, topic='/imu/other',
                      extra_topics={'/imu/data_raw': ('sensor_msgs/msg/Imu', [])})
        return path, ['--topic', '/imu/data_raw']
    write_imu_bag(path, s)
    return path, []


@pytest.mark.parametrize('kind,needle', [
    ('nan', 'nan'), ('inf', 'inf'), ('backwards', 'do not increase'), ('jump', 'jump'),
    ('short', 'too short'), ('empty_topic', 'no messages')])
def test_bad_bag_data_one_line_exit_2_nothing_written(tmp_path, kind, needle):
    path, extra = _bad_bag(tmp_path, kind)
    out = tmp_path / 'out'
    proc = run_command('analyze', path, *extra, '--out', out)
    assert proc.returncode == 2, proc.stdout
    line = proc.stderr.strip()
    assert '\n' not in line and 'Traceback' not in line
    assert str(path) in line and needle in line.lower(), line
    assert not out.exists()


def test_bad_bag_files_one_line_exit_2(tmp_path, shared_data):
    cases = []
    garbage = tmp_path / 'garbage.mcap'
    garbage.write_bytes(np.random.default_rng(1).bytes(4000))
    cases.append(([garbage], 'garbage.mcap'))
    good = tmp_path / 'good'
    write_imu_bag(good, _samples())
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes((good / 'good.mcap').read_bytes()[:200])
    cases.append(([cut], 'cut.mcap'))
    cases.append(([shared_data / 'bags' / 'test1.bag', '--topic',
                   '/husky_velocity_controller/odom'], 'odom'))
    cases.append(([tmp_path / 'missing_bag'], 'missing_bag'))
    for args, needle in cases:
        proc = run_command('analyze', *args)
        assert proc.returncode == 2, (args, proc.stdout)
        assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert needle in proc.stderr and 'Traceback' not in proc.stderr


def test_damaged_bag_readable_part_analysed_with_warning(tmp_path):
    good = tmp_path / 'long'
    write_imu_bag(good, _samples(n=60_000))
    data = (good / 'long.mcap').read_bytes()
    cut = tmp_path / 'truncated.mcap'
    cut.write_bytes(data[: int(len(data) * 0.6)])
    rep = _json(cut)
    assert 1000 < rep['n_samples'] < 60_000
    assert any('skip' in w.lower() or 'truncat' in w.lower() for w in rep['verdict']['warnings'])
    assert all(math.isfinite(v) for v in rep['axes']['gyro_x']['adev']['adev'])
