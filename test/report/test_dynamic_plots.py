"""``analyze --dynamic``: the report.json block, the console lines and the two PNGs."""

import json
import math

from conftest import run_command
from imu_allan import simulate, thesis_gx3_25_model
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import matplotlib.image
import numpy as np
import pytest

pytestmark = pytest.mark.ros

RATE = 100.0


@pytest.mark.slow
def test_dynamic_block_plots_and_console(tmp_path):
    """A white-noise step x1.5 on gyro_y after 40 of 80 min: one change, on gyro_y, named."""
    n = int(80 * 60 * RATE)
    data = simulate(thesis_gx3_25_model(), n, RATE, seed=21)
    data[:, 5] += 9.80665
    tc = n // 2
    white = 5.73e-4 * math.sqrt(RATE) * np.random.default_rng(4).standard_normal(n - tc)
    data[tc:, 1] += white * math.sqrt(1.5 ** 2 - 1.0)  # N x 1.5 from tc on
    path = tmp_path / 'step.csv'
    write_csv(path, Samples(t=500.0 + np.arange(n) / RATE, data=data))
    out = tmp_path / 'out'
    proc = run_command('analyze', path, '--dynamic', '--out', out)
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / 'report.json').read_text())
    dyn = report['dynamic']
    assert dyn['window_s'] == 200.0 or abs(dyn['window_s'] - 200.0) < 10.0  # 80 min / 24
    assert abs(dyn['step_s'] - dyn['window_s'] / 4) < 1e-9
    assert dyn['false_alarm_rate_per_day'] is not None
    assert [(c['axis'], c['what']) for c in dyn['changes']] == [('gyro_y', 'white_noise')]
    change = dyn['changes'][0]
    assert abs(change['t_s'] - tc / RATE) <= dyn['step_s']
    assert 1.3 < change['ratio'] < 1.7
    assert 'gyro_y   white_noise' in proc.stdout
    for sensor in ('gyro', 'accel'):
        image = matplotlib.image.imread(out / f'dynamic_{sensor}.png')
        assert image.shape[0] > 300 and image[..., :3].std() > 0.05  # a drawn figure


def test_dynamic_too_short_is_one_line_exit_2(tmp_path):
    """Shorter than two windows: one line naming the input, exit 2."""
    n = int(100 * RATE)
    data = simulate(thesis_gx3_25_model(), n, RATE, seed=2)
    path = tmp_path / 'short.csv'
    write_csv(path, Samples(t=np.arange(n) / RATE, data=data))
    proc = run_command('analyze', path, '--dynamic', '60')
    assert proc.returncode == 2 and proc.stdout == ''
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and 'short.csv' in lines[0] and 'two windows' in lines[0], lines
