"""
The DuckDB history of ``analyze --db FILE``: tables ``inputs`` and ``measurements``.

One row of ``inputs`` per analysed input (its absolute path, size, modification time, status,
error, when and by which version), and the noise coefficients of the ``ok`` ones in
``measurements``, one row per (axis, term, parameter).  The schema is part of the contract
(docs/interfaces.md).

DuckDB lets one process at a time open a database file for writing.  So that several runs can
share a file, a run opens it only to write what has just finished (one transaction per input)
and closes it again; a process that finds the file locked retries for up to
:data:`LOCK_WAIT_S`.  An input's old rows
are deleted in the same transaction that inserts its new ones, so a crash leaves either the old
or the new rows of an input, never half of them and never both.
"""

import contextlib
from datetime import datetime, timedelta, timezone
import os
from pathlib import Path
import time

from ..errors import InputError

#: How long a run waits for another process to release the database file, s.
LOCK_WAIT_S = 120.0
INSTALL_HINT = "the history needs duckdb: pip install 'duckdb>=1.5'"

SCHEMA = """
CREATE TABLE IF NOT EXISTS inputs (
    input VARCHAR NOT NULL,        -- absolute path of the file or rosbag2 folder
    size BIGINT,                   -- bytes (a folder: the sum of its files)
    mtime TIMESTAMP,               -- UTC, last modification (a folder: its newest file)
    status VARCHAR NOT NULL,       -- 'ok' | 'error'
    error VARCHAR,                 -- the one-line reason when status = 'error'
    analyzed_at TIMESTAMP NOT NULL,  -- UTC
    version VARCHAR NOT NULL       -- imu_allan version that analysed it
);
CREATE TABLE IF NOT EXISTS measurements (
    input VARCHAR NOT NULL,
    topic VARCHAR,
    imu_id VARCHAR NOT NULL,
    start_utc TIMESTAMP,           -- first sample's stamp, UTC
    duration_s DOUBLE,
    rate_hz DOUBLE,
    axis VARCHAR NOT NULL,
    term VARCHAR NOT NULL,
    param VARCHAR NOT NULL,        -- 'value', or sigma, tau_c, amplitude, frequency_hz
    value DOUBLE,                  -- SI, continuous-time
    ci_low DOUBLE,                 -- 68.3 % interval (NULL for upper limits)
    ci_high DOUBLE,
    unit VARCHAR,                  -- SI unit of value
    detected BOOLEAN NOT NULL,     -- false: value is a 95 % upper limit
    static BOOLEAN,                -- the static verdict of the record
    analyzed_at TIMESTAMP NOT NULL
);
"""
INPUT_COLUMNS = ('input', 'size', 'mtime', 'status', 'error', 'analyzed_at', 'version')
MEASUREMENT_COLUMNS = ('input', 'topic', 'imu_id', 'start_utc', 'duration_s', 'rate_hz', 'axis',
                       'term', 'param', 'value', 'ci_low', 'ci_high', 'unit', 'detected',
                       'static', 'analyzed_at')


def utc(seconds):
    """Return a naive UTC datetime (DuckDB TIMESTAMP) from seconds since 1970 (float)."""
    return datetime(1970, 1, 1) + timedelta(seconds=float(seconds))


def utc_now():
    """Now, as a naive UTC datetime."""
    return datetime.now(timezone.utc).replace(tzinfo=None)


def fingerprint(path):
    """``(size in bytes, mtime)`` of a file, or of a folder's files (sum, newest); UTC."""
    p = Path(path)
    if p.is_dir():
        stats = [f.stat() for f in sorted(p.rglob('*')) if f.is_file()]
    else:
        stats = [p.stat()]
    size = sum(s.st_size for s in stats)
    newest = max((s.st_mtime_ns for s in stats), default=0)
    # microseconds: the resolution of a DuckDB TIMESTAMP, so the value read back compares equal
    return size, datetime(1970, 1, 1) + timedelta(microseconds=newest // 1000)


def _duckdb(where):
    try:
        import duckdb
    except ImportError:
        raise InputError(where, INSTALL_HINT) from None
    return duckdb


@contextlib.contextmanager
def connect(path, read_only=False, wait_s=LOCK_WAIT_S):
    """Open the database (created with the schema unless ``read_only``), waiting out locks."""
    duckdb = _duckdb(path)
    if read_only and not Path(path).exists():
        raise InputError(path, 'no such database')
    deadline = time.monotonic() + wait_s
    delay = 0.05
    while True:
        try:
            con = duckdb.connect(str(path), read_only=read_only)
            break
        except duckdb.IOException as err:
            text = ' '.join(str(err).split())
            if 'lock' not in text.lower():
                raise InputError(path, text[:200]) from None
            if time.monotonic() > deadline:
                raise InputError(path, f'database still locked by another process after '
                                       f'{wait_s:g} s') from None
            time.sleep(delay)
            delay = min(2.0 * delay, 1.0)
    try:
        if not read_only:
            con.execute(SCHEMA)
        yield con
    finally:
        con.close()


def known_inputs(path):
    """``{input: (size, mtime)}`` of every input already recorded (empty if no database)."""
    if not Path(path).exists():
        _duckdb(path)
        return {}
    with connect(path) as con:
        rows = con.execute('SELECT input, size, mtime FROM inputs').fetchall()
    return {inp: (size, mtime) for inp, size, mtime in rows}


def record(con, entry, rows):
    """
    Write one input: its ``inputs`` row and its ``measurements`` rows, in one transaction.

    ``con`` an open connection (:func:`connect`); ``entry`` a dict of :data:`INPUT_COLUMNS`,
    ``rows`` one dict of :data:`MEASUREMENT_COLUMNS` per measurement.
    """
    inp = entry['input']
    con.execute('BEGIN TRANSACTION')
    try:
        con.execute('DELETE FROM measurements WHERE input = ?', [inp])
        con.execute('DELETE FROM inputs WHERE input = ?', [inp])
        con.execute(f'INSERT INTO inputs ({", ".join(INPUT_COLUMNS)}) VALUES '
                    f'({", ".join("?" * len(INPUT_COLUMNS))})',
                    [entry[c] for c in INPUT_COLUMNS])
        if rows:
            # one statement with many VALUES: executemany costs a round trip per row
            one = '(' + ', '.join('?' * len(MEASUREMENT_COLUMNS)) + ')'
            con.execute(f'INSERT INTO measurements ({", ".join(MEASUREMENT_COLUMNS)}) '
                        f'VALUES {", ".join([one] * len(rows))}',
                        [r[c] for r in rows for c in MEASUREMENT_COLUMNS])
        con.execute('COMMIT')
    except BaseException:
        con.execute('ROLLBACK')
        raise


def abspath(path):
    """Return the absolute form of an input path as stored in the ``input`` columns."""
    return os.path.abspath(str(path).rstrip('/') or '/')
