"""
The DuckDB history: one transaction per input, waiting out another process's lock, ids.

Budget: about 5 s (one helper process holds the file for 2 s).
"""

from datetime import datetime
import os
import subprocess
import sys
import time

import duckdb
from imu_allan.errors import InputError
from imu_allan.history import db
from imu_allan.history.rows import imu_id_of, namespace_of
import pytest

ENTRY = {'input': '/bags/a.mcap', 'size': 10, 'mtime': datetime(2026, 1, 1), 'status': 'ok',
         'error': None, 'analyzed_at': datetime(2026, 1, 2), 'version': '0.1.0'}


def _row(value, axis='gyro_x'):
    return {'input': '/bags/a.mcap', 'topic': '/r1/imu/data_raw', 'imu_id': 'r1/imu',
            'start_utc': datetime(2026, 1, 1), 'duration_s': 60.0, 'rate_hz': 50.0,
            'axis': axis, 'term': 'white_noise', 'param': 'value', 'value': value,
            'ci_low': 0.9, 'ci_high': 1.1, 'unit': 'rad/s/sqrt(Hz)', 'detected': True,
            'static': True, 'analyzed_at': datetime(2026, 1, 2)}


def _count(path):
    with db.connect(path, read_only=True) as con:
        return (con.execute('SELECT count(*) FROM inputs').fetchone()[0],
                con.execute('SELECT count(*), sum(value) FROM measurements').fetchone())


def test_rewrite_replaces_and_a_failed_write_leaves_the_old_rows(tmp_path):
    path = tmp_path / 'h.duckdb'
    with db.connect(path) as con:
        db.record(con, ENTRY, [_row(1.0), _row(2.0, 'gyro_y')])
        db.record(con, ENTRY, [_row(3.0)])  # the same input again: replaced, not doubled
    assert _count(path) == (1, (1, 3.0))
    with db.connect(path) as con, pytest.raises(duckdb.ConversionException):
        # the second row fails to convert after the deletes and the first inserts ran
        db.record(con, ENTRY, [_row(5.0), _row('not a number')])
    assert _count(path) == (1, (1, 3.0))


def test_a_locked_file_is_waited_for(tmp_path):
    path = tmp_path / 'h.duckdb'
    with db.connect(path):
        pass
    holder = subprocess.Popen([sys.executable, '-c', (
        'import duckdb, sys, time\n'
        'con = duckdb.connect(sys.argv[1]); print("locked", flush=True); time.sleep(2.0)\n'
        'con.close()'), str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == 'locked'
        with pytest.raises(InputError, match='still locked'):
            with db.connect(path, wait_s=0.3):
                pass
        t0 = time.monotonic()
        with db.connect(path) as con:
            db.record(con, ENTRY, [_row(1.0)])
        assert time.monotonic() - t0 > 0.5  # it waited for the other process
    finally:
        holder.wait(timeout=30)
    assert _count(path) == (1, (1, 1.0))


def test_bad_database_files_are_one_line_errors(tmp_path):
    with pytest.raises(InputError, match='no such database'):
        with db.connect(tmp_path / 'none.duckdb', read_only=True):
            pass
    junk = tmp_path / 'junk.duckdb'
    junk.write_text('hello')
    with pytest.raises(InputError, match='not a valid DuckDB'):
        with db.connect(junk):
            pass


def test_fingerprint_of_a_folder_follows_its_files(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text('x')
    (bag / 'bag_0.mcap').write_bytes(b'12345')
    size, mtime = db.fingerprint(bag)
    assert size == 6
    os.utime(bag / 'bag_0.mcap', ns=(0, 1_800_000_000_123_456_789))
    assert db.fingerprint(bag) == (6, datetime(2027, 1, 15, 8, 0, 0, 123456))


@pytest.mark.parametrize('topic, frame_id, expected', [
    ('/robot3/imu/data_raw', 'imu_link', 'robot3/imu_link'),
    ('/imu/data_raw', 'imu_link', 'imu_link'),
    ('/fleet/r7/sensors/imu/data', 'base_imu', 'fleet/r7/sensors/base_imu'),
    ('/r2/imu_raw', 'imu', 'r2/imu'),
    ('/r2/imu_raw', '', 'r2/rec'),
    (None, '', 'rec'),
])
def test_imu_id(topic, frame_id, expected):
    assert imu_id_of(topic, frame_id, '/data/rec.csv') == expected
    assert namespace_of(topic) == expected.rpartition('/')[0]
