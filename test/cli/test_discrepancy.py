"""The ``discrepancy`` command (built executable), its JSON contract, plots and bad input."""

import json
import math

from conftest import run_command
from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.discrepancy import gap_summary
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros

RATE = 100.0
MINUTES = 20.0
BASE = {'white_noise': {'value': 1e-3}, 'bias_instability': {'value': 3e-4}}
# gyro_x hides a rate random walk (crosses the flicker floor near 3 s), gyro_y is clean
TRUTH = NoiseModel({'gyro_x': {**BASE, 'rate_random_walk': {'value': 2.5e-4}},
                    'gyro_y': dict(BASE)}, RATE)


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """Return a 20 min, 100 Hz CSV with two gyro axes (seeded)."""
    n = int(MINUTES * 60 * RATE)
    data = simulate(TRUTH, n, RATE, seed=11)
    path = tmp_path_factory.mktemp('disc') / 'two_axes.csv'
    write_csv(path, Samples(np.arange(n) / RATE, data, ('gyro_x', 'gyro_y'), 'test'))
    return path, data


@pytest.fixture(scope='module')
def json_run(recording):
    """``discrepancy INPUT --json --sims 2``: exit status, parsed stdout, stderr."""
    path, _ = recording
    proc = run_command('discrepancy', path, '--json', '--sims', '2', timeout=300)
    return proc


def test_help_exits_zero():
    proc = run_command('discrepancy', '--help')
    assert proc.returncode == 0
    assert '--model' in proc.stdout and '--terms' in proc.stdout and '--json' in proc.stdout


@pytest.mark.slow
def test_json_follows_the_contract(json_run):
    assert json_run.returncode == 0, json_run.stderr
    report = json.loads(json_run.stdout)  # --json: the report and nothing else on stdout
    assert report['initial_terms'] == ['white_noise', 'bias_instability']
    assert 'rate_random_walk' in report['final_terms']
    assert set(report['gap']) == {'gyro_x', 'gyro_y'}
    for entry in report['gap'].values():
        assert math.isfinite(entry['initial']) and math.isfinite(entry['final'])
    steps = report['steps']
    assert [s['axis'] for s in steps] == ['gyro_x']
    step = steps[0]
    assert step['effect'] == 'rate_random_walk'
    lo, hi = step['tau_range_s']
    assert 0 < lo < hi <= MINUTES * 60 / 10 + 1e-9
    assert step['gap_before'] > report['gap']['gyro_x']['threshold']  # clearly inconsistent
    assert step['gap_after'] == report['gap']['gyro_x']['final']
    assert report['gap']['gyro_x']['consistent'] is True
    k = step['parameters']['value']
    assert k['unit'] == 'rad/s^2/sqrt(Hz)'
    # true K = 2.5e-4 inside the 95 % interval; 68 % interval nested inside it
    assert k['ci95'][0] <= 2.5e-4 <= k['ci95'][1]
    assert k['ci95'][0] <= k['ci'][0] <= k['value'] <= k['ci'][1] <= k['ci95'][1]
    assert report['gap']['gyro_y']['final'] < report['gap']['gyro_y']['threshold']


@pytest.mark.slow
def test_out_dir_has_report_model_and_plots(recording, json_run, tmp_path):
    path, _ = recording
    out = tmp_path / 'out'
    proc = run_command('discrepancy', path, '--out', out, '--sims', '2', timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert 'gyro_x' in proc.stdout and 'rate_random_walk' in proc.stdout  # console summary
    report = json.loads((out / 'report.json').read_text())
    assert report['steps'] == json.loads(json_run.stdout)['steps']  # same seed, same answer
    final = NoiseModel.from_yaml(out / 'final_model.yaml')
    assert 'rate_random_walk' in final.terms['gyro_x']
    pngs = sorted(p.name for p in out.glob('*.png'))
    assert 'gap_per_step.png' in pngs and 'overview.png' in pngs
    assert any(p.startswith('step01_gyro_x_rate_random_walk') for p in pngs)
    for name in pngs:
        head = (out / name).read_bytes()[:8]
        assert head == b'\x89PNG\r\n\x1a\n', name


@pytest.mark.slow
def test_model_file_start(recording, tmp_path):
    """Starting from the (exact) two-term model file, the missing RRW is still found."""
    path, _ = recording
    model_file = tmp_path / 'start.yaml'
    NoiseModel({'gyro_x': BASE, 'gyro_y': BASE}, RATE).to_yaml(model_file)
    proc = run_command('discrepancy', path, '--model', model_file, '--json', '--sims', '1',
                       timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert [(s['axis'], s['effect']) for s in report['steps']] == [
        ('gyro_x', 'rate_random_walk')]
    assert report['start'] == 'model'


@pytest.mark.parametrize('args, needle', [
    (['{missing}'], 'no such file'),
    (['{csv}', '--terms', 'white_noise,warp_drive'], 'warp_drive'),
    (['{csv}', '--model', '{badyaml}'], 'bad.yaml'),
    (['{csv}', '--model', '{badterm}'], 'badterm.yaml'),
    (['{short}'], 'short.csv'),
    (['{csv}', '--model', '{badyaml}', '--terms', 'white_noise'], 'not allowed'),
])
def test_bad_input_is_one_line_and_status_2(recording, tmp_path, args, needle):
    path, data = recording
    (tmp_path / 'bad.yaml').write_text('gyro: [unclosed\n')
    (tmp_path / 'badterm.yaml').write_text('gyro:\n  white_noise: -1.0\n')
    short = tmp_path / 'short.csv'
    write_csv(short, Samples(np.arange(30) / RATE, data[:30], ('gyro_x', 'gyro_y'), 'test'))
    names = {'missing': tmp_path / 'nope.csv', 'csv': path, 'badyaml': tmp_path / 'bad.yaml',
             'badterm': tmp_path / 'badterm.yaml', 'short': short}
    proc = run_command('discrepancy', *[a.format(**names) for a in args], timeout=120)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert 'Traceback' not in proc.stderr
    assert needle in lines[0]
    assert proc.stdout == ''


def test_gap_summary_for_the_online_hook(recording):
    """The allan node's hook: gap per axis and the effect that fits the excess."""
    _, data = recording
    result = allan_deviation(data, RATE, axes=('gyro_x', 'gyro_y'))
    model = NoiseModel({'gyro_x': BASE, 'gyro_y': BASE}, RATE)
    summary = gap_summary(model, result)
    assert set(summary) == {'gyro_x', 'gyro_y'}
    assert summary['gyro_x']['effect'] == 'rate_random_walk'
    assert summary['gyro_x']['consistent'] is False and summary['gyro_x']['gap'] > 2.0
    assert summary['gyro_y']['effect'] is None and summary['gyro_y']['consistent'] is True
    assert 0.3 < summary['gyro_y']['gap'] < 1.6


@pytest.mark.slow
def test_real_moving_robot_bag(shared_data, tmp_path):
    """A real (moving, so not static) Jackal bag: the command runs and reports every axis."""
    bag = shared_data / 'bags' / 'jackal_test2_mcap'
    proc = run_command('discrepancy', bag, '--json', '--sims', '0', timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report['n_samples'] == 3061
    assert abs(report['sample_rate_hz'] - 50.0) < 0.1
    assert len(report['gap']) == 6
    # driving is not white noise + flicker: the workflow finds the start lacking and adds
    # named effects, each one lowering that axis's gap below where it started
    assert report['steps']
    known = {'quantization', 'white_noise', 'bias_instability', 'rate_random_walk', 'rate_ramp',
             'gauss_markov', 'sinusoid'}
    assert {s['effect'] for s in report['steps']} <= known
    for axis, gap in report['gap'].items():
        assert gap['final'] <= gap['initial'], axis
    # and it says that the IMU moved, so the named effects describe the motion
    assert any('not static' in note for note in report['notes'])
