"""
``fleet``: trends and flags from a DuckDB history of 5 simulated IMUs over 12 weeks.

The history is written through the same code path as ``analyze --db`` (``History.record``
with the report of ``analyze_samples`` on each record), but from samples simulated in memory:
60 bags would cost the test a minute of writing and reading that the Dask test already covers.
One gyro and one accelerometer axis keep the 60 analyses cheap (the fleet logic is per axis).
Budget: about 20 s unloaded (60 one-minute two-axis analyses at 50 Hz, three fleet runs).
"""

from datetime import datetime
import json

from conftest import run_command
from imu_allan import NoiseModel, simulate
from imu_allan.cli.batch import History
from imu_allan.core.analysis import AnalysisOptions, analyze_samples
from imu_allan.formats.samples import Samples
from imu_allan.history.db import connect, utc
from imu_allan.report.json_report import analysis_to_json
import numpy as np
import pytest

pytestmark = pytest.mark.ros

GYRO_N, ACCEL_N = 5.8e-4, 8.3e-4
RATE, N = 50.0, 3000  # one minute at 50 Hz: N to about +-1.3 % (68.3 %)
IMUS, WEEKS, WORSE, RISE = 5, 12, 3, 1.3  # robot3's white noise +30 % in the last 3 weeks
T0 = 1_767_571_200.0  # 2026-01-05 00:00 UTC, a Monday
WEEK = 7 * 86400.0
OPTIONS = AnalysisOptions(terms=['white_noise', 'bias_instability'])


AXES = ('gyro_x', 'accel_x')


def _model(scale):
    return NoiseModel.from_dict({'axes': {
        'gyro_x': {'white_noise': GYRO_N * scale, 'bias_instability': 1.5e-4},
        'accel_x': {'white_noise': ACCEL_N * scale, 'bias_instability': 7e-4}}})


@pytest.fixture(scope='module')
def fleet_db(tmp_path_factory):
    """Weekly one-minute still records of robot0..robot4 (same IMU model, own seeds)."""
    db = tmp_path_factory.mktemp('fleet') / 'history.duckdb'
    history = History(db)
    with history.session():
        for robot in range(IMUS):
            for week in range(WEEKS):
                worse = robot == 3 and week >= WEEKS - WORSE
                data = simulate(_model(RISE if worse else 1.0), N, RATE,
                                seed=1000 * robot + week)
                start = T0 + week * WEEK + robot * 3600.0
                samples = Samples(t=start + np.arange(N) / RATE, data=data, axes=AXES,
                                  topic=f'/robot{robot}/imu/data_raw', frame_id='imu_link')
                report = analysis_to_json(analyze_samples(samples, OPTIONS), samples)
                path = f'/fleet/robot{robot}/week{week:02d}.mcap'
                history.record({'input': path, 'ok': True, 'report': report},
                               (100_000, utc(start + 120.0)))
    return db


def test_history_has_every_record_once(fleet_db):
    with connect(fleet_db, read_only=True) as con:
        assert con.execute('SELECT count(*), count(DISTINCT input) FROM inputs').fetchone() \
            == (IMUS * WEEKS, IMUS * WEEKS)
        ids = [r[0] for r in con.execute('SELECT DISTINCT imu_id FROM measurements '
                                         'ORDER BY 1').fetchall()]
        first = con.execute('SELECT min(start_utc) FROM measurements').fetchone()[0]
    assert ids == [f'robot{k}/imu_link' for k in range(IMUS)]  # namespace / frame_id
    assert first == datetime(2026, 1, 5)


@pytest.mark.slow
def test_exactly_the_degrading_imu_is_flagged(fleet_db, tmp_path):
    """
    robot3's N rose 30 % (about 20 of its interval half-widths): flagged; nobody else.

    Every healthy IMU faces 8 history tests (2 axes x N, B x rise, fall) at about 4 sigma and
    4 fleet tests, so a false flag among the four would be a 1-in-100 event, not the seed's.
    """
    out = tmp_path / 'report'
    proc = run_command('fleet', fleet_db, '--out', out, '--json')
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert {f['imu_id'] for f in report['flags']} == {'robot3/imu_link'}
    kinds = {(f['kind'], f['sensor'], f['term']) for f in report['flags']}
    for sensor in ('gyro', 'accel'):  # its own history and the fleet's 95th percentile
        assert ('history', sensor, 'white_noise') in kinds
        assert ('fleet', sensor, 'white_noise') in kinds
    for flag in report['flags']:
        ref = flag['reference']
        if flag['kind'] == 'history':
            assert flag['ci'][0] > ref['band'][1]
        else:
            assert flag['value'] - ref['margin'] > ref['p95']
        assert flag['start_utc'].startswith('2026-03-23')  # week 12 of 2026-01-05
    assert [e['records'] for e in report['imus']] == [WEEKS] * IMUS
    assert [e['flagged'] for e in report['imus']] == [False, False, False, True, False]
    pngs = sorted(p.name for p in out.glob('*.png'))
    assert pngs == [f'robot{k}_imu_link.png' for k in range(IMUS)]
    assert json.loads((out / 'fleet.json').read_text())['flags'] == report['flags']
    # the text form: the same flags, one line each, saying why
    text = run_command('fleet', fleet_db, '--out', out).stdout
    lines = [ln.strip() for ln in text.splitlines() if ln.startswith('  robot')]
    assert lines == [f['why'] for f in report['flags']]
    assert all('rose above its own history' in ln or "fleet's 95th percentile" in ln
               for ln in lines)


@pytest.mark.slow
def test_since_and_bad_input(fleet_db, tmp_path):
    proc = run_command('fleet', fleet_db, '--out', tmp_path, '--json', '--since', '2026-02-02')
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert [e['records'] for e in report['imus']] == [8] * IMUS  # weeks 5..12
    assert {f['imu_id'] for f in report['flags']} == {'robot3/imu_link'}
    for args, where in (((tmp_path / 'none.duckdb',), 'no such database'),
                        ((fleet_db, '--since', 'last week'), 'not an ISO 8601 date'),
                        ((fleet_db, '--since', '2027-01-01'), 'no static measurements')):
        proc = run_command('fleet', *args, '--out', tmp_path)
        assert proc.returncode == 2
        assert len(proc.stderr.splitlines()) == 1 and where in proc.stderr, proc.stderr
