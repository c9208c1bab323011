"""
Hostile command lines: one clean line and exit 2, never a traceback or a hang.

Real subprocesses of the built executables, each bounded by a timeout.  Most cases fail at
argument or file checks, before any numerics (about a second each); one small analysis checks
that a result which cannot be written is an error.
"""

import subprocess

from conftest import executable, run_command
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest


def _one_clean_line(proc, *needles):
    assert proc.returncode == 2, (proc.stdout, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in proc.stderr, proc.stderr
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def small_csv(tmp_path):
    rng = np.random.default_rng(0)
    path = tmp_path / 'rec.csv'
    write_csv(path, Samples(t=np.arange(3000) / 100.0, data=rng.normal(0, 1e-3, (3000, 6))))
    return path


@pytest.mark.parametrize('option, value', [
    ('--rate', 'inf'), ('--rate', 'nan'), ('--rate', '-5'), ('--jobs', '-3'),
    ('--points-per-decade', '100000'), ('--min-clusters', str(10**12)), ('--tau-max', '0'),
    ('--jobs', '1e3')])
def test_numeric_options_bounded(small_csv, option, value):
    """Every numeric option has bounds: out of them is a usage error naming the option."""
    _one_clean_line(run_command('analyze', small_csv, option, value, timeout=60), option)


@pytest.mark.parametrize('content', [
    b'gyro: 5\n', b'axes: [1, 2]\n', b'gyro: {white_noise: 1.0e+300}\n',
    b'gyro: {white_noise: ' + b'9' * 400 + b'}\n', b'[' * 5000 + b']' * 5000,
    b'gyro: {white_noise: true}\n', b'rate_hz: -1\n', b'\x89PNG\r\n\x1a\n\x00\x00binary'])
def test_discrepancy_malformed_model_names_the_model_file(small_csv, tmp_path, content):
    """The model file, not the data, is named; the schema of core/model.py says what is wrong."""
    model = tmp_path / 'model.yaml'
    model.write_bytes(content)
    proc = run_command('discrepancy', small_csv, '--model', model, timeout=120)
    _one_clean_line(proc, str(model))


def test_devices_and_unwritable_out_refused_before_any_work(small_csv, tmp_path):
    """/dev/zero is not read forever; an --out that is a file is refused before the analysis."""
    _one_clean_line(run_command('analyze', '/dev/zero', timeout=60), '/dev/zero', 'a device')
    blocker = tmp_path / 'report'
    blocker.write_text('a file, not a folder')
    _one_clean_line(run_command('analyze', small_csv, '--out', blocker, timeout=60),
                    'not a folder')
    _one_clean_line(run_command('analyze', small_csv, '--export-samples',
                                tmp_path / 'missing' / 'x.csv', timeout=120), 'cannot write')
    assert not (tmp_path / 'missing').exists()


def test_json_to_a_closed_stdout_is_an_error(small_csv):
    """The result cannot be delivered: exit 2 with the reason, not a silent exit 0."""
    proc = subprocess.run(f'exec "{executable("analyze")}" "{small_csv}" --json >&-',
                          shell=True, capture_output=True, text=True, timeout=300)
    _one_clean_line(proc, 'stdout')
