"""
``discrepancy DATA --model FILE.sdf`` (built executable): a Gazebo SDF as the model under test.

The data are the re-implemented gz-sensors noise of ``EXAMPLE_SDF`` (``formats/sim_reference``)
plus a rate random walk on gyro_x that the file lacks; 15 min at 100 Hz, fixed seeds.
"""

import json

from conftest import run_command
from formats.sim_reference import EXAMPLE_SDF, gz_noise_params, gz_simulate
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros

RATE = 100.0
N = 15 * 60 * 100
AXES = ('gyro_x', 'gyro_y')


@pytest.fixture(scope='module')
def files(tmp_path_factory):
    """Return the recording (CSV) and the simulator's file the data do not fully follow."""
    folder = tmp_path_factory.mktemp('sdf')
    data = gz_simulate(gz_noise_params(EXAMPLE_SDF), AXES, N, RATE, seed=1)
    hidden = NoiseModel({'gyro_x': {'rate_random_walk': {'value': 3e-4}}})
    data[:, 0] += simulate(hidden, N, RATE, seed=2)[:, 0]
    csv = folder / 'gazebo_run.csv'
    write_csv(csv, Samples(np.arange(N) / RATE, data, AXES, 'test'))
    sdf = folder / 'robot.sdf'
    sdf.write_text(EXAMPLE_SDF)
    return csv, sdf, folder


@pytest.mark.slow
def test_sdf_model_names_the_effect_and_corrected_sdf_closes_the_gap(files):
    """
    The random walk is named on gyro_x; corrected.sdf, run again, starts with a smaller gap.

    The second run starts from corrected.sdf: the workflow's own simulation of what that file
    really simulates must be closer to the data (initial gap of gyro_x below half the first
    run's; measured 6.9 -> about 2.6) and gyro_y unchanged.
    """
    csv, sdf, folder = files
    out = folder / 'out'
    first = run_command('discrepancy', csv, '--model', sdf, '--json', '--sims', '2',
                        '--out', out, timeout=300)
    assert first.returncode == 0, first.stderr
    report = json.loads(first.stdout)
    assert [s['effect'] for s in report['steps'] if s['axis'] == 'gyro_x'][-1] == \
        'rate_random_walk'
    assert not [s for s in report['steps'] if s['axis'] == 'gyro_y']
    assert any('stddev / sqrt(f)' in note for note in report['notes'])
    corrected = out / 'corrected.sdf'
    text = corrected.read_text()
    assert text.startswith('<!--') and 'added rate_random_walk' in text
    assert gz_noise_params(text)['gyro_y'] == gz_noise_params(EXAMPLE_SDF)['gyro_y']

    second = run_command('discrepancy', csv, '--model', corrected, '--json', '--sims', '2',
                         timeout=300)
    assert second.returncode == 0, second.stderr
    again = json.loads(second.stdout)
    assert again['gap']['gyro_x']['initial'] < 0.5 * report['gap']['gyro_x']['initial']
    assert again['gap']['gyro_y']['initial'] == pytest.approx(
        report['gap']['gyro_y']['initial'], rel=0.2)


def test_bad_sdf_is_one_line_and_exit_2(files):
    """One case through the command (the reader's cases are in formats/test_gazebo_sdf.py)."""
    csv, _, folder = files
    bad = folder / 'bad.sdf'
    bad.write_text('<imu><angular_velocity><x><noise type="gaussian"><stddev>-0.1</stddev>'
                   '</noise></x></angular_velocity></imu>')
    proc = run_command('discrepancy', csv, '--model', bad)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and str(bad) in lines[0] and 'stddev is negative' in lines[0], \
        proc.stderr
