"""Benchmark: ``analyze`` end to end on a 10-hour, 100 Hz, 6-axis bag (3.6 M Imu messages).

Writes the bag once (MCAP, Jazzy's default; and sqlite3), then times the built ``analyze``
executable as a user runs it (process start, reading, Allan deviation, intervals, fit with term
selection, Kalibr limits, verdicts; ``--json`` so no plots), and ``--out`` with plots.
Goal: under 15 s.  Usage: ``python bench/bench_analyze.py [HOURS]``.
"""

import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np

from imu_allan import simulate, thesis_gx3_25_model
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples


def _analyze_exe():
    from ament_index_python.packages import get_package_prefix
    return str(Path(get_package_prefix('imu_allan')) / 'lib' / 'imu_allan' / 'analyze')


def main():
    """Write the bags, time analyze on each, print the results."""
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    n = int(hours * 3600 * 100)
    data = simulate(thesis_gx3_25_model(), n, 100.0, seed=5)
    data[:, 5] += 9.80665
    samples = Samples(t=1.7e9 + np.arange(n) / 100.0, data=data)
    exe = _analyze_exe()
    with tempfile.TemporaryDirectory(prefix='bench_analyze_') as tmp:
        for storage in ('mcap', 'sqlite3'):
            bag = Path(tmp) / f'static_{storage}'
            t0 = time.perf_counter()
            write_imu_bag(bag, samples, storage=storage)
            print(f'analyze: wrote {n} Imu messages ({hours:g} h at 100 Hz) as {storage} in '
                  f'{time.perf_counter() - t0:.1f} s')
            for extra in (['--json'], ['--out', str(Path(tmp) / f'out_{storage}'), '--quiet']):
                t0 = time.perf_counter()
                proc = subprocess.run([exe, str(bag), *extra], capture_output=True, text=True,
                                      env=dict(os.environ))
                wall = time.perf_counter() - t0
                if proc.returncode != 0:
                    print(proc.stderr)
                    return 1
                print(f'analyze: {storage} {" ".join(extra[:1])}: {wall:.1f} s end to end '
                      f'(goal < 15 s)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
