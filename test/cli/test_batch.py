"""
``analyze`` on a real Dask cluster with a DuckDB history (imu_allan.cli.batch).

A real ``dask scheduler`` and two ``dask worker`` processes (Dask's own command line, on
127.0.0.1, random ports, no dashboard) analyse a folder of 21 small bags in all three
containers (rosbag2 MCAP and sqlite3 folders, bare .mcap/.db3 files, ROS 1 .bag) plus one
corrupt bag.  Budget: about 40 s unloaded (63 one-minute analyses, five processes started).
"""

import json
import os
from pathlib import Path
import shutil
import signal
import socket
import subprocess
import sys

from conftest import executable, run_command
from imu_allan import NoiseModel, simulate
from imu_allan.cli.analyze import _options, build_parser
from imu_allan.cli.batch import analyze_task, scan_inputs
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
from imu_allan.history.db import connect, MEASUREMENT_COLUMNS
from imu_allan.history.rows import measurement_rows
import numpy as np
import pytest

pytestmark = pytest.mark.ros

MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.8e-4, 'bias_instability': 1.5e-4},
                              'accel': {'white_noise': 8.3e-4, 'bias_instability': 7e-4}})
RATE, N = 50.0, 3000  # one minute at 50 Hz
# three terms fitted: no upper-limit profiles, the cheapest fit (the numbers are what matter)
OPTIONS = ['--terms', 'white_noise,bias_instability,rate_random_walk']
STORAGES = ('mcap', 'sqlite3', 'ros1')
GOOD = 21


@pytest.fixture(scope='module')
def bag_folder(tmp_path_factory):
    """robot<k>/ folders with 7 bags of each container; one bare .mcap and .db3; one corrupt."""
    root = tmp_path_factory.mktemp('bags')
    for i in range(GOOD):
        robot, storage = i % 3, STORAGES[i % 3 if i < 18 else i - 18]
        data = simulate(MODEL, N, RATE, seed=500 + i)
        data[:, 5] += 9.80665
        samples = Samples(t=1.7e9 + 86400.0 * i + np.arange(N) / RATE, data=data)
        folder = root / f'robot{robot}'
        folder.mkdir(exist_ok=True)
        path = folder / (f'rec{i:02d}.bag' if storage == 'ros1' else f'rec{i:02d}')
        write_imu_bag(path, samples, topic=f'/robot{robot}/imu/data_raw', storage=storage,
                      frame_id='imu_link')
    for name in ('rec00', 'rec01'):  # bare storage files outside any rosbag2 folder
        folder = root / 'robot0' / name if name == 'rec00' else root / 'robot1' / name
        store = next(folder.glob('*.mcap')) if name == 'rec00' else next(folder.glob('*.db3'))
        shutil.move(store, root / store.name)
        shutil.rmtree(folder)
    good = root / 'robot2' / 'rec02.bag'
    (root / 'robot2' / 'corrupt.bag').write_bytes(good.read_bytes()[:400])
    (root / 'notes.csv').write_text('t,gyro_x\n0,1\n1,2\n')  # CSV: only when named
    return root


@pytest.fixture(scope='module')
def cluster(tmp_path_factory):
    """Start a real scheduler and two single-threaded workers without nanny (a kill is a death)."""
    dask = str(Path(sys.executable).parent / 'dask')
    env = dict(os.environ, DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES='2',
               OPENBLAS_NUM_THREADS='1', NUMBA_NUM_THREADS='1')
    logs = tmp_path_factory.mktemp('dask')
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    address = f'tcp://127.0.0.1:{port}'
    procs = [subprocess.Popen([dask, 'scheduler', '--host', '127.0.0.1', '--port', str(port),
                               '--no-dashboard'], env=env, stdout=subprocess.DEVNULL,
                              stderr=open(logs / 'scheduler.log', 'w'))]
    try:
        for k in range(2):
            procs.append(subprocess.Popen(
                [dask, 'worker', address, '--host', '127.0.0.1', '--nthreads', '1',
                 '--no-nanny', '--no-dashboard', '--name', f'w{k}'], env=env,
                stdout=subprocess.DEVNULL, stderr=open(logs / f'worker{k}.log', 'w')))
        from distributed import Client
        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield address, procs[1:]
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _rows(db):
    with connect(db, read_only=True) as con:
        inputs = con.execute('SELECT input, status, error FROM inputs ORDER BY input').fetchall()
        cols = ', '.join(c for c in MEASUREMENT_COLUMNS if c != 'analyzed_at')
        meas = con.execute(f'SELECT {cols} FROM measurements '
                           'ORDER BY input, axis, term, param').fetchall()
    return inputs, meas


def _serial(paths):
    """Return the serial path: the same per-input function, here, one input after another."""
    args = build_parser().parse_args(['x', *OPTIONS])
    out = {}
    for p in paths:
        outcome = analyze_task(str(p), args, _options(args))
        assert outcome['ok'], outcome
        out[os.path.abspath(p)] = outcome['report']
    return out


def test_scan_finds_every_bag_and_no_csv(bag_folder):
    inputs, counts = scan_inputs([str(bag_folder), str(bag_folder / 'robot0')])
    assert len(inputs) == GOOD + 1  # robot0 again adds nothing
    assert dict(counts) == {'rosbag2 folder': 12, '.mcap': 1, '.db3': 1, 'ROS 1 .bag': 8}
    assert not any(p.endswith('.csv') for p in inputs)


@pytest.mark.slow
def test_cluster_run_equals_serial_then_skips_then_survives_a_dead_worker(
        bag_folder, cluster, tmp_path):
    address, workers = cluster
    db = tmp_path / 'history.duckdb'
    inputs, _ = scan_inputs([str(bag_folder)])
    good = [p for p in inputs if 'corrupt' not in p]
    serial = _serial(good)

    # 1. the whole folder on the cluster: 21 reports equal to the serial ones, 1 error row
    proc = run_command('analyze', bag_folder, '--scheduler', address, '--db', db, '--json',
                       *OPTIONS, timeout=600)
    assert proc.returncode == 2, proc.stderr
    out = json.loads(proc.stdout)
    assert len(out['reports']) == GOOD and len(out['errors']) == 1
    assert 'corrupt.bag' in out['errors'][0] and '\n' not in out['errors'][0]
    assert 'analyze: 22 input(s)' in proc.stderr
    by_source = {r['source'].rsplit(':', 1)[0]: r for r in out['reports']}
    for path, ref in serial.items():
        rep = by_source[path]
        for axis, block in ref['axes'].items():
            for term, entry in block['terms'].items():
                got = rep['axes'][axis]['terms'][term]
                np.testing.assert_allclose([got['value'], *got['ci']],
                                           [entry['value'], *entry['ci']], rtol=1e-12)
    inputs_rows, meas = _rows(db)
    assert len(inputs_rows) == GOOD + 1
    assert [r[1] for r in inputs_rows].count('error') == 1
    error_row = next(r for r in inputs_rows if r[1] == 'error')
    assert error_row[0].endswith('corrupt.bag') and 'corrupt.bag' in error_row[2]
    expected = []
    for path, ref in serial.items():
        expected += [tuple(r[c] for c in MEASUREMENT_COLUMNS if c != 'analyzed_at')
                     for r in measurement_rows(ref, path, None)]
    assert len(meas) == len(expected)
    for got, want in zip(meas, sorted(expected, key=lambda r: (r[0], r[6], r[7], r[8]))):
        assert got[:9] == want[:9] and got[12:] == want[12:]  # ids, units, flags
        np.testing.assert_allclose([x if x is not None else np.nan for x in got[9:12]],
                                   [x if x is not None else np.nan for x in want[9:12]],
                                   rtol=1e-12)
    assert {r[2] for r in meas} == {f'robot{k}/imu_link' for k in range(3)}

    # 2. again: everything is already there with the same size and mtime
    proc = run_command('analyze', bag_folder, '--scheduler', address, '--db', db, '--json',
                       *OPTIONS, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == {'reports': [], 'errors': [],
                                       'skipped': inputs}
    assert '22 input(s) already in' in proc.stderr

    # 3. --force with one worker killed after the first result: all 22 answered exactly once
    run = subprocess.Popen([executable('analyze'), str(bag_folder), '--scheduler', address,
                            '--db', str(db), '--force', *OPTIONS],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in run.stderr:  # plain progress lines off a terminal: "[1/22, 0 failed] ..."
        if line.startswith('['):
            break
    workers[0].send_signal(signal.SIGKILL)
    stdout, stderr = run.communicate(timeout=600)
    assert workers[0].wait(timeout=10) == -signal.SIGKILL
    assert run.returncode == 2, stderr
    assert 'corrupt.bag' in stderr and '21 analysed, 1 failed' in stdout
    inputs_after, meas_after = _rows(db)
    assert inputs_after == inputs_rows  # nothing missing, nothing doubled
    assert len(meas_after) == len(meas)
    for a, b in zip(meas_after, meas):
        assert a[:9] == b[:9]
        np.testing.assert_allclose([x if x is not None else np.nan for x in a[9:12]],
                                   [x if x is not None else np.nan for x in b[9:12]],
                                   rtol=1e-12)


@pytest.mark.slow
def test_without_dask_and_duckdb_one_input_works_and_the_options_say_what_to_install(
        bag_folder, tmp_path):
    """dask, distributed and duckdb shadowed by packages that fail to import (as if absent)."""
    for name in ('dask', 'distributed', 'duckdb'):
        (tmp_path / name).mkdir()
        (tmp_path / name / '__init__.py').write_text(f'raise ImportError("no {name}")\n')
    env = dict(os.environ, PYTHONPATH=f'{tmp_path}:{os.environ.get("PYTHONPATH", "")}')
    bag = bag_folder / 'robot1' / 'rec04'
    proc = run_command('analyze', bag, '--json', *OPTIONS, env=env)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)['n_samples'] == N
    for args, needs in ((('--scheduler', 'tcp://127.0.0.1:9'), "pip install 'dask"),
                        (('--db', tmp_path / 'h.duckdb'), 'pip install')):
        proc = run_command('analyze', bag, *args, *OPTIONS, env=env)
        assert proc.returncode == 2
        assert len(proc.stderr.splitlines()) == 1 and needs in proc.stderr, proc.stderr
    # several inputs still work, one after another in this process
    proc = run_command('analyze', bag, bag_folder / 'robot2' / 'rec05.bag', '--json', *OPTIONS,
                       env=env)
    assert proc.returncode == 0 and len(json.loads(proc.stdout)['reports']) == 2
    assert 'dask is not installed' in proc.stderr
