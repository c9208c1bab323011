"""``analyze --estimators``: extra deviations in report.json and on the plots; bad kinds."""

import json

from conftest import run_command
from imu_allan import deviation, simulate, thesis_gx3_25_model
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros


@pytest.fixture(scope='module')
def short_csv(tmp_path_factory):
    n = 100 * 300  # 5 min at 100 Hz
    data = simulate(thesis_gx3_25_model(), n, 100.0, seed=5)
    data[:, 5] += 9.80665
    path = tmp_path_factory.mktemp('csv') / 'still.csv'
    write_csv(path, Samples(t=np.arange(n) / 100.0, data=data))
    return path, data


@pytest.mark.slow
def test_estimators_in_report_and_plots(short_csv, tmp_path):
    path, data = short_csv
    out = tmp_path / 'out'
    proc = run_command('analyze', path, '--estimators', 'oadev,mdev,ohdev,totdev,theo1',
                       '--out', out, '--quiet')
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / 'report.json').read_text())
    for entry in report['axes'].values():
        assert set(entry['deviations']) == {'mdev', 'ohdev', 'totdev', 'theo1'}
        for curve in entry['deviations'].values():
            assert set(curve) == {'tau', 'dev', 'ci_low', 'ci_high', 'edf'}
            assert len(curve['tau']) == len(curve['dev']) == len(curve['edf']) > 3
            assert all(lo < d < hi for lo, d, hi in zip(curve['ci_low'], curve['dev'],
                                                        curve['ci_high']))
    # The numbers are the API's on the same samples (the CSV keeps 9 significant digits).
    mdev = deviation(data[:, :1], 100.0, 'mdev')
    np.testing.assert_allclose(report['axes']['gyro_x']['deviations']['mdev']['dev'],
                               mdev.dev[:, 0], rtol=1e-5)
    assert any(out.glob('*.png'))


def test_default_has_no_extra_curves(short_csv):
    proc = run_command('analyze', short_csv[0], '--json')
    assert proc.returncode == 0, proc.stderr
    assert all('deviations' not in e for e in json.loads(proc.stdout)['axes'].values())


def test_unknown_estimator_is_one_line_exit_2(short_csv):
    proc = run_command('analyze', short_csv[0], '--estimators', 'oadev,foodev', '--json')
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and 'foodev' in lines[0] and '--estimators' in lines[0]


@pytest.mark.slow
def test_ohdev_decides_a_walk_against_a_ramp(tmp_path):
    """
    ``--estimators ohdev``: the Hadamard curve rejects a rate random walk the Allan fit left open.

    gyro_x: 1 h at 100 Hz of N 2e-3, B 2e-4 and a rate ramp of 3e-6 rad/s^2 (seed 6): the Allan
    fit selects N R and leaves N K open beside it; the Hadamard curve, blind to the ramp,
    allows less walk than N K needs, and N K leaves the open sets (N K R, where the ramp
    carries the rise, stays).  Without OHDEV N K stays open and is said so.
    """
    from imu_allan import NoiseModel
    n = 360_000
    ramp = NoiseModel.from_dict({'gyro': {'white_noise': 2e-3, 'bias_instability': 2e-4,
                                          'rate_ramp': 3e-6}})
    data = simulate(thesis_gx3_25_model(), n, 100.0, seed=1)
    data[:, 0] = simulate(ramp, n, 100.0, seed=6, axes=['gyro_x'])[:, 0]
    data[:, 5] += 9.80665
    path = tmp_path / 'ramp.csv'
    write_csv(path, Samples(t=np.arange(n) / 100.0, data=data))
    nk = ['white_noise', 'rate_random_walk']
    plain = run_command('analyze', path, '--json')
    assert plain.returncode == 0, plain.stderr
    fit = json.loads(plain.stdout)['axes']['gyro_x']['fit']
    assert nk in fit['alternatives'] and fit['rejected'] == [] and fit['decided_by'] is None
    checked = run_command('analyze', path, '--estimators', 'oadev,ohdev', '--json')
    assert checked.returncode == 0, checked.stderr
    fit = json.loads(checked.stdout)['axes']['gyro_x']['fit']
    assert [r['terms'] for r in fit['rejected']] == [nk]
    assert fit['rejected'][0]['by'] == 'ohdev'
    assert nk not in fit['alternatives']
