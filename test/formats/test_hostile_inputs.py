"""
Hostile text, raw and special-file inputs at the readers.

* CSV time columns in ms, us or ns are recognised from the sample spacing: converted with a
  warning that says so, or refused with the reason when the unit cannot be told;
* FIFOs are read once a writer appears and refused (not waited on forever) without one;
  devices such as /dev/zero are refused at once;
* a raw capture that lost packets counts them from the device timer's true spacing.
Every case is a few hundred samples; the FIFO waits are 0.5 s.
"""

import os
import threading
import time

from imu_allan.core.checks.preprocess import check_timing
from imu_allan.device.gx3_protocol import encode_record
from imu_allan.errors import InputError
from imu_allan.formats import input_file
from imu_allan.formats.csv_samples import read_csv
from imu_allan.formats.gx3raw import read_gx3raw
from imu_allan.formats.readers import read_samples
import numpy as np
import pytest

N = 400


def _csv(path, t):
    values = np.random.default_rng(0).normal(0.0, 1e-3, t.shape[0])
    path.write_text('t,gyro_x\n' + ''.join(f'{a!r},{b!r}\n'
                                           for a, b in zip(t.tolist(), values.tolist())))
    return path


@pytest.mark.parametrize('rate', [100.0, 400.0])
@pytest.mark.parametrize('unit, per_s, start', [('ms', 1e3, 0.0), ('ns', 1e9, 0.0),
                                                ('us', 1e6, 1.7e15), ('ns', 1e9, 1.7e18)])
def test_csv_time_unit_converted_with_a_warning(tmp_path, rate, unit, per_s, start):
    """A unique unit (or absolute Unix stamps) gives the rate back, with a warning naming it."""
    s = read_csv(_csv(tmp_path / 'a.csv', start + np.arange(N) * per_s / rate))
    assert 1.0 / np.median(np.diff(s.t)) == pytest.approx(rate, rel=1e-4)
    assert len(s.warnings) == 1 and f't read as {unit}' in s.warnings[0]


def test_csv_seconds_untouched_and_ambiguous_units_refused(tmp_path):
    """Seconds stay seconds, silently; 1000 per step (1 Hz in ms or 1 kHz in us) is refused."""
    s = read_csv(_csv(tmp_path / 's.csv', np.arange(N) / 100.0))
    assert not s.warnings and np.median(np.diff(s.t)) == pytest.approx(0.01)
    with pytest.raises(InputError, match=r'ms \(1 Hz\) or us \(1000 Hz\)\? write t in seconds'):
        read_csv(_csv(tmp_path / 'amb.csv', np.arange(N) * 1000.0))
    with pytest.raises(InputError, match='no unit'):
        read_csv(_csv(tmp_path / 'none.csv', np.arange(N) * 1e15))


def test_devices_refused_at_once():
    """/dev/zero never ends, /dev/null is not a recording: refused in every format."""
    for fmt in ('auto', 'csv', 'thesis', 'gx3raw', 'rosbag2'):
        for dev in ('/dev/zero', '/dev/null'):
            with pytest.raises(InputError, match='a device, not a recording'):
                read_samples(dev, fmt=fmt)


def test_fifo_without_writer_is_an_error_not_a_hang(tmp_path, monkeypatch):
    """No writer within the wait: one line saying so."""
    monkeypatch.setattr(input_file, 'FIFO_WAIT_S', 0.5)
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)
    start = time.monotonic()
    with pytest.raises(InputError, match='a FIFO with no writer'):
        read_samples(fifo)
    assert time.monotonic() - start < 5.0


def test_fifo_with_a_writer_reads_like_the_file(tmp_path, monkeypatch):
    """A CSV through a FIFO gives the file's samples; the source names the FIFO."""
    monkeypatch.setattr(input_file, 'FIFO_WAIT_S', 5.0)
    src = _csv(tmp_path / 'a.csv', np.arange(N) / 100.0)
    fifo = tmp_path / 'pipe'
    os.mkfifo(fifo)

    def write():
        time.sleep(0.2)
        with open(fifo, 'wb') as out:
            out.write(src.read_bytes())
    writer = threading.Thread(target=write)
    writer.start()
    got = read_samples(fifo)
    writer.join(5)
    ref = read_csv(src)
    assert np.array_equal(got.t, ref.t) and np.array_equal(got.data, ref.data)
    assert got.source == str(fifo)


@pytest.mark.parametrize('seed', range(3))
def test_raw_capture_losses_counted_from_the_device_timer(tmp_path, seed):
    """42 % of packets lost, mostly every other one: 100 Hz with the losses counted."""
    rng = np.random.default_rng(seed)
    n = 3000
    keep = np.ones(n, bool)
    keep[1::2] = rng.random(n // 2) > 0.84
    packets = [encode_record(0xC2, rng.normal(0.0, 1e-3, 6), 625 * i)
               for i in range(n) if keep[i]]
    path = tmp_path / 'lossy.bin'
    path.write_bytes(b''.join(packets))
    s = read_gx3raw(path)
    lost = int(n - keep.sum() - (not keep[-1]))
    assert any(f'about {lost} packet(s) missing' in w for w in s.warnings)
    timing = check_timing(s.t)  # what the analysis uses
    assert timing.rate_hz == pytest.approx(100.0) and timing.missing_samples == lost


def test_csv_read_in_blocks_with_a_line_limit(tmp_path, monkeypatch):
    """
    Blocks of lines give the same samples; a bad line in a later block is named exactly.

    A file with no line breaks is refused after MAX_LINE characters, not read whole.
    """
    from imu_allan.formats import csv_samples
    path = _csv(tmp_path / 'a.csv', np.arange(N) / 100.0)
    whole = read_csv(path)
    monkeypatch.setattr(csv_samples, '_ROWS', 37)
    blocked = read_csv(path)
    assert np.array_equal(whole.t, blocked.t) and np.array_equal(whole.data, blocked.data)
    lines = path.read_text().splitlines()
    lines[300] = '3.0,abc'
    path.write_text('\n'.join(lines) + '\n')
    with pytest.raises(InputError, match="line 301, column gyro_x: not a number: 'abc'"):
        read_csv(path)
    endless = tmp_path / 'endless.csv'
    endless.write_text('t,gyro_x\n' + '1' * (csv_samples.MAX_LINE + 10))
    with pytest.raises(InputError, match='line 2: longer than'):
        read_csv(endless)


def test_thesis_log_stamp_beyond_int64_is_a_damaged_line(tmp_path):
    """A stamp with too many digits (found by the fuzz test) is skipped and counted."""
    from imu_allan.formats.thesis_log import read_thesis_log
    good = [f'0.0; 0.0; 1.0; 0.001; 0.002; 0.003; {1445776339557671000 + i * 10_000_000}'
            for i in range(5)]
    path = tmp_path / 'log.txt'
    path.write_text('\n'.join(good[:2] + [good[2] + '9' * 10] + good[3:]) + '\n')
    s = read_thesis_log(path)
    assert s.n == 4 and '1 malformed line(s) skipped (line 3)' in s.warnings[0]
