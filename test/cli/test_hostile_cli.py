"""
Hostile command lines: one clean line and exit 2, never a traceback or a hang.

Real subprocesses of the built executables, each bounded by a timeout.  Most cases fail at
argument or file checks, before any numerics (about a second each); one small analysis checks
that a result which cannot be written is an error.
"""

import json
import struct
import subprocess

from conftest import executable, run_command
from imu_allan.formats.bag_writer import fix_mcap_chunk_crcs, write_imu_bag
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

pytestmark = pytest.mark.ros


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


@pytest.mark.parametrize('seed', [1, 2])
def test_one_stamp_gone_back_in_a_bag_is_dropped_not_fatal(tmp_path, seed):
    """
    One message's header stamp went back: dropped with a warning, exit 0 (as the node does).

    The issue's case (CRC intact, so only the stamp rule sees it); a second bad stamp right
    after it refuses the bag as before.
    """
    rng = np.random.default_rng(seed)
    n = 3000
    samples = Samples(t=1.7e9 + np.arange(n) / 100.0, data=rng.normal(0, 1e-3, (n, 6)))
    folder = write_imu_bag(tmp_path / 'bag', samples, storage='mcap')
    path = next(folder.glob('*.mcap'))
    raw = bytearray(path.read_bytes())
    # The CDR message data start 31 bytes into a Message record (opcode 0x05): encapsulation
    # 00 01 00 00, then the header stamp's int32 seconds.  Found by those bytes.
    u8 = np.frombuffer(bytes(raw), dtype=np.uint8)
    i = np.flatnonzero(u8[:-40] == 0x05)
    i = i[(u8[i + 31] == 0) & (u8[i + 32] == 1) & (u8[i + 33] == 0) & (u8[i + 34] == 0)]
    sec = np.array([struct.unpack_from('<i', raw, j + 35)[0] for j in i.tolist()])
    hits = i[(sec >= 1_700_000_000) & (sec <= 1_700_000_000 + n // 100)].tolist()
    assert len(hits) == n
    k = int(rng.integers(100, len(hits) - 100))
    struct.pack_into('<i', raw, hits[k] + 35, 1_699_999_000)
    path.write_bytes(bytes(raw))
    fix_mcap_chunk_crcs(folder)
    proc = run_command('analyze', path, '--json', timeout=300)
    assert proc.returncode == 0, proc.stderr
    warnings = json.loads(proc.stdout)['verdict']['warnings']
    assert any(w.startswith('1 isolated out-of-order') and f'sample(s) {k} ' in w
               for w in warnings), warnings
    struct.pack_into('<i', raw, hits[k + 1] + 35, 1_699_999_000)
    path.write_bytes(bytes(raw))
    fix_mcap_chunk_crcs(folder)
    _one_clean_line(run_command('analyze', path, '--json', timeout=300), 'not isolated')
