"""
Hostile numbers in the containers' integer fields: range-checked where they are decoded.

The MCAP Message record's ``log_time`` is a u64 on disk; beyond int64 it once reached
``np.asarray(..., dtype=np.int64)`` and ended in an OverflowError traceback.  Each case writes
a real bag with the package's writer, sets the field to an out-of-range value at seeded
positions (restoring the chunk CRC, so only the range check can catch it), and asserts: the
other samples unchanged, the damaged records counted in a warning that names the problem,
never an exception.  Both the numpy and the compiled (numba) walk are run.
"""

import struct

from conftest import run_command
from imu_allan.formats import collector, imu_cdr, mcap_scan, scan_common
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import fix_mcap_chunk_crcs, write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np
import pytest

N = 3000


def _samples():
    rng = np.random.default_rng(0)
    return Samples(t=1.7e9 + np.arange(N) / 100.0, data=rng.normal(0.0, 1e-3, (N, 6)))


def _message_offsets(raw):
    """Byte offsets of every Message record inside the (uncompressed) chunks of an MCAP."""
    out, pos = [], 8
    while pos + 9 <= len(raw):
        op = raw[pos]
        (length,) = struct.unpack_from('<Q', raw, pos + 1)
        if op == 0x06:
            (n,) = struct.unpack_from('<I', raw, pos + 37)
            assert raw[pos + 41:pos + 41 + n] == b''  # the writer's default: uncompressed
            (csize,) = struct.unpack_from('<Q', raw, pos + 41 + n)
            inner = pos + 49 + n
            p = inner
            while p < inner + csize:
                (ln,) = struct.unpack_from('<Q', raw, p + 1)
                if raw[p] == 0x05:
                    out.append(p)
                p += 9 + ln
        elif op in (0x0F, 0x02):
            break
        pos += 9 + length
    return np.array(out)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """Return a valid MCAP (bytes), its samples as read, and its Message record offsets."""
    folder = write_imu_bag(tmp_path_factory.mktemp('ok') / 'bag', _samples(), storage='mcap')
    src = next(folder.glob('*.mcap'))
    raw = src.read_bytes()
    offsets = _message_offsets(raw)
    assert offsets.size == N
    return raw, read_bag(src), offsets


def _damage(tmp_path, raw, at, values):
    """Write a copy with log_time set to ``values`` at the records ``at``, CRCs restored."""
    buf = bytearray(raw)
    for pos, value in zip(at.tolist(), values):
        struct.pack_into('<Q', buf, pos + 15, value)
    folder = tmp_path / 'damaged'
    folder.mkdir(exist_ok=True)
    path = folder / 'bag_0.mcap'
    path.write_bytes(bytes(buf))
    fix_mcap_chunk_crcs(folder)
    return path


@pytest.mark.parametrize('walk', ['numpy', 'compiled'])
def test_mcap_log_time_beyond_int64_is_a_counted_damaged_record(tmp_path, bag, walk,
                                                                monkeypatch):
    """Seeded positions (a lone record, a run, the first and last): skipped and counted."""
    raw, ref, offsets = bag
    if walk == 'compiled':
        if scan_common.compiled_walks(True) is None:
            pytest.skip('numba walk not available')
        monkeypatch.setattr(mcap_scan, 'COMPILED_MIN_BYTES', 0)
    rng = np.random.default_rng(26)
    cases = [np.array([0]), np.array([N - 1]), np.arange(100, 140)]
    cases += [np.sort(rng.choice(N, size=int(rng.integers(1, 30)), replace=False))
              for _ in range(12)]
    for k, idx in enumerate(cases):
        values = rng.integers(1 << 63, (1 << 64) - 1, size=idx.size, dtype=np.uint64,
                              endpoint=True).tolist()
        got = read_bag(_damage(tmp_path, raw, offsets[idx], values))
        keep = np.setdiff1d(np.arange(N), idx)
        assert np.array_equal(got.t, ref.t[keep]) and np.array_equal(got.data, ref.data[keep])
        assert collector.bad_time_warning(idx.size) in got.warnings, (k, got.warnings)


def test_mcap_log_time_at_the_int64_edge_is_kept(tmp_path, bag):
    """2^63 - 1 is still a time (the record sorts last); 2^63 is not."""
    raw, ref, offsets = bag
    got = read_bag(_damage(tmp_path, raw, offsets[[5]], [collector.INT64_MAX]))
    assert got.n == N and not any('out of range' in w for w in got.warnings)
    assert got.t[-1] == ref.t[5]
    got = read_bag(_damage(tmp_path, raw, offsets[[5]], [collector.INT64_MAX + 1]))
    assert got.n == N - 1 and collector.bad_time_warning(1) in got.warnings


def test_collector_receive_times_from_sql_rows_checked():
    """The SQL fallback's rows: a None, a float or a 2^63 receive time is a damaged record."""
    rows, stamps = imu_cdr.encode_imu(np.arange(6) / 100.0, np.zeros((6, 6)))
    coll = collector.Collector(False, imu_cdr.deserialize)
    times = stamps.tolist()
    times[1], times[3], times[4] = None, 1 << 63, 2.5
    coll.add_blobs(times, [r.tobytes() for r in rows])
    t, _ = coll.result()
    assert np.array_equal(t, np.array([0, 2, 5]) / 100.0)
    assert coll.warnings() == [collector.bad_time_warning(3)]


@pytest.mark.ros
def test_analyze_of_a_bag_with_an_out_of_range_log_time(tmp_path, bag):
    """The issue's case end to end: exit 0, the warning in the JSON, no traceback."""
    import json
    raw, _, offsets = bag
    path = _damage(tmp_path, raw, offsets[[1234]], [(1 << 64) - 1])
    proc = run_command('analyze', path, '--json', timeout=300)
    assert proc.returncode == 0 and 'Traceback' not in proc.stderr, proc.stderr
    assert collector.bad_time_warning(1) in json.loads(proc.stdout)['verdict']['warnings']
