"""
Property-based fuzzing of every parser: arbitrary bytes and mutated valid files.

Each reader is called in-process on (a) arbitrary bytes and (b) a valid file of its format
with seeded byte flips and a truncation. The property: it returns well-formed samples (or a
model/budget) or raises :class:`~imu_allan.errors.InputError`; never another exception and
never a hang (each call runs under a 10 s alarm). Hypothesis runs derandomized with a bounded
number of examples so the whole file takes a few seconds.
"""

import contextlib
import signal

from hypothesis import given, HealthCheck, settings
from hypothesis import strategies as st
from imu_allan.core.live.health import NoiseBudget
from imu_allan.core.model import NoiseModel
from imu_allan.device.gx3_protocol import encode_record
from imu_allan.errors import InputError
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.csv_samples import read_csv, write_csv
from imu_allan.formats.gx3raw import read_gx3raw
from imu_allan.formats.samples import Samples
from imu_allan.formats.thesis_log import read_thesis_log
import numpy as np
import pytest

FUZZ = settings(derandomize=True, max_examples=40, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow,
                                       HealthCheck.function_scoped_fixture])
N = 300  # samples in each valid file


@contextlib.contextmanager
def no_hang(seconds=10):
    """Fail (TimeoutError) instead of hanging when a call takes longer than ``seconds``."""
    def alarm(_sig, _frame):
        raise TimeoutError(f'parser took more than {seconds} s')
    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _samples():
    rng = np.random.default_rng(1)
    data = np.column_stack([rng.normal(0, 0.01, (N, 3)),
                            rng.normal(0, 0.05, (N, 3)) + [0, 0, 9.8]])
    return Samples(t=1000.0 + np.arange(N) * 0.01, data=data)


def _thesis_text():
    s = _samples()
    lines = ['Acceleration vector needs to be scaled by gravity modulus at measure location: '
             '9.80261']
    for i in range(N):
        accel_g = s.data[i, 3:] / 9.80261
        fields = [f'{v:.9f}' for v in (*accel_g, *s.data[i, :3])]
        lines.append('; '.join(fields) + f'; {1445776339557671000 + i * 10_000_000}')
    return ('\n'.join(lines) + '\n').encode()


def _gx3raw_bytes():
    s = _samples()
    return b''.join(encode_record(0xC2, [*(s.data[i, 3:] / 9.80665), *s.data[i, :3]],
                                  1000 + 625 * i) for i in range(N))


MODEL = b'rate_hz: 100.0\ngyro:\n  white_noise: 5.8e-4\n  bias_instability: 1.5e-4\n' \
        b'accel:\n  white_noise: 8.3e-4\naxes:\n  gyro_z:\n    gauss_markov: {sigma: 1.0e-4, ' \
        b'tau_c: 30.0}\n    sinusoid: {amplitude: 1.0e-4, frequency_hz: 0.5}\n'
BUDGET = b'warn_ratio: 1.0\nerror_ratio: 2.0\ngyro: {white_noise: 5.2e-4, bias_instability: ' \
         b'8.7e-5}\naccel: {white_noise: 7.8e-4}\naxes: {gyro_z: {bias_instability: 1.0e-4}}\n'


def _check_samples(s):
    assert s.t.ndim == 1 and s.data.shape == (s.t.shape[0], len(s.axes))
    assert all(isinstance(w, str) and '\n' not in w for w in s.warnings)


READERS = {
    'csv': (read_csv, _check_samples),
    'thesis': (read_thesis_log, _check_samples),
    'gx3raw': (read_gx3raw, _check_samples),
    'mcap': (read_bag, _check_samples),
    'sqlite3': (read_bag, _check_samples),
    'ros1': (read_bag, _check_samples),
    'model': (NoiseModel.from_yaml, lambda m: m.axes),
    'budget': (NoiseBudget.from_yaml, lambda b: b.limits),
}


@pytest.fixture(scope='module')
def valid(tmp_path_factory):
    """One valid file per format: name -> (bytes, suffix)."""
    d = tmp_path_factory.mktemp('valid')
    out = {}
    write_csv(d / 'a.csv', _samples())
    out['csv'] = ((d / 'a.csv').read_bytes(), '.csv')
    out['thesis'] = (_thesis_text(), '.log')
    out['gx3raw'] = (_gx3raw_bytes(), '.bin')
    for storage, suffix in (('mcap', '.mcap'), ('sqlite3', '.db3')):
        folder = write_imu_bag(d / storage, _samples(), storage=storage)
        out[storage] = (next(folder.glob(f'*{suffix}')).read_bytes(), suffix)
    write_imu_bag(d / 'b.bag', _samples(), storage='ros1')
    out['ros1'] = ((d / 'b.bag').read_bytes(), '.bag')
    out['model'] = (MODEL, '.yaml')
    out['budget'] = (BUDGET, '.yaml')
    return out


def _run(name, path):
    read, check = READERS[name]
    with no_hang():
        try:
            result = read(path)
        except InputError as exc:
            assert '\n' not in str(exc) and str(exc).strip()
            return
    check(result)


def test_valid_files_read(valid, tmp_path):
    """The unmutated files are valid for their reader (so the mutations start from valid)."""
    for name, (raw, suffix) in valid.items():
        path = tmp_path / f'{name}{suffix}'
        path.write_bytes(raw)
        result = READERS[name][0](path)
        READERS[name][1](result)


@pytest.mark.parametrize('name', sorted(READERS))
@FUZZ
@given(raw=st.binary(max_size=2048))
def test_arbitrary_bytes(tmp_path, name, raw):
    """Arbitrary bytes under each reader's own suffix: InputError or samples, nothing else."""
    path = tmp_path / f'fuzz{".bag" if name == "ros1" else ".mcap" if name == "mcap" else ""}'
    path.write_bytes(raw)
    _run(name, path)


@pytest.mark.parametrize('name', sorted(READERS))
@FUZZ
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)),
                      min_size=1, max_size=20),
       cut=st.floats(0.05, 1.0))
def test_mutated_valid_files(valid, tmp_path, name, flips, cut):
    """Seeded byte flips and a truncation of a valid file: InputError or samples."""
    raw, suffix = valid[name]
    buf = bytearray(raw[:max(1, int(len(raw) * cut))])
    for where, value in flips:
        buf[int(where * len(buf))] = value
    path = tmp_path / f'mutated{suffix}'
    path.write_bytes(bytes(buf))
    _run(name, path)
