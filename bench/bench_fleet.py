"""
Benchmark: ``analyze`` on many bags, a local Dask cluster against one process.

Writes DISTINCT one-hour 100 Hz 6-axis MCAP bags (different seeds) and makes BAGS inputs of
them as hard links (bare ``.mcap`` files: every input is a separate path, read and analysed
in full; the page cache holds the DISTINCT files).  Then times:

* one process: the per-input function (``cli.batch.analyze_task``) in a loop, in this process;
* the ``analyze`` command on the folder with its default local cluster (one single-threaded
  worker process per core), start-up and shut-down included;
* the scheduler's cost per input: the command on TINY inputs (10 s at 100 Hz) minus the
  in-process time of the same inputs, per input, with the cluster start-up measured apart.

Usage: ``python bench/bench_fleet.py [BAGS [DISTINCT [HOURS [TINY]]]]`` (default 200 10 1 200).
"""

import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

from imu_allan import simulate, thesis_gx3_25_model
from imu_allan.cli.analyze import _options, build_parser
from imu_allan.cli.batch import analyze_task
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np


def _exe():
    from ament_index_python.packages import get_package_prefix
    return str(Path(get_package_prefix('imu_allan')) / 'lib' / 'imu_allan' / 'analyze')


def _make(folder, count, distinct, seconds):
    folder.mkdir()
    store = folder.parent / f'{folder.name}_store'
    store.mkdir()
    n = int(seconds * 100)
    sources = []
    for k in range(distinct):
        data = simulate(thesis_gx3_25_model(), n, 100.0, seed=100 + k)
        data[:, 5] += 9.80665
        bag = store / f'b{k}'
        write_imu_bag(bag, Samples(t=1.7e9 + np.arange(n) / 100.0, data=data), storage='mcap')
        sources.append(next(bag.glob('*.mcap')))
    for i in range(count):
        os.link(sources[i % distinct], folder / f'in{i:04d}.mcap')
    return sorted(str(p) for p in folder.glob('*.mcap'))


def _serial(inputs):
    args = build_parser().parse_args(['x', '--quiet'])
    options = _options(args)
    t0 = time.perf_counter()
    for p in inputs:
        assert analyze_task(p, args, options)['ok']
    return time.perf_counter() - t0


def _command(folder):
    t0 = time.perf_counter()
    proc = subprocess.run([_exe(), str(folder), '--json', '--quiet'], capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(proc.stderr)
    return wall


def main():
    """Write the inputs, time both ways, print the figures."""
    argv = [float(x) for x in sys.argv[1:]]
    count, distinct, hours, tiny = (argv + [200, 10, 1, 200][len(argv):])[:4]
    count, distinct, tiny = int(count), int(distinct), int(tiny)
    with tempfile.TemporaryDirectory(prefix='bench_fleet_') as tmp:
        t0 = time.perf_counter()
        big = _make(Path(tmp) / 'big', count, distinct, hours * 3600)
        print(f'fleet: {count} inputs of {hours:g} h at 100 Hz ({distinct} distinct bags, '
              f'{os.path.getsize(big[0]) / 1e6:.0f} MB each) written in '
              f'{time.perf_counter() - t0:.0f} s')
        one = _serial(big)
        cluster = _command(Path(tmp) / 'big')
        print(f'fleet: one process {one:.1f} s ({count / one:.2f} inputs/s); local cluster '
              f'({os.cpu_count()} workers) {cluster:.1f} s ({count / cluster:.2f} inputs/s); '
              f'speed-up {one / cluster:.2f}')
        small = _make(Path(tmp) / 'tiny', tiny, 1, 10.0)
        _make(Path(tmp) / 'two', 2, 1, 10.0)
        base = _command(Path(tmp) / 'two')
        run = _command(Path(tmp) / 'tiny')
        compute = _serial(small) / tiny
        per_input = (run - base) / (tiny - 2) - compute / os.cpu_count()
        print(f'fleet: tiny inputs (10 s at 100 Hz): {compute * 1e3:.0f} ms of analysis each; '
              f'command with 2 inputs {base:.1f} s (start-up); {tiny} inputs {run:.1f} s; '
              f'scheduler overhead {per_input * 1e3:.0f} ms per input')
    return 0


if __name__ == '__main__':
    sys.exit(main())
