"""
Benchmark: peak memory of reading a long recording, and of ``analyze``, against its size.

Writes HOURS of 100 Hz six-axis samples as a contract CSV, MCAP and sqlite3 rosbag2 and a
ROS 1 bag into a temporary folder, then reads each in a fresh process (``read_samples``, what
``analyze`` does first) and runs the whole ``analyze --json`` on the CSV, MCAP and sqlite3
recordings in another.  Printed: the peak resident set size (``VmHWM``), the decoded arrays'
size (t and data, float64) and the peak above the process's own baseline (the modules imported
and numba's runtime loaded, nothing read) divided by the decoded size.  Goal: at most 1.5x.
Usage: ``python bench/bench_memory.py [HOURS]`` (default 10).
"""

from pathlib import Path
import subprocess
import sys
import tempfile

from benchlib import goal, header
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np

# numba's runtime (llvmlite's library, numba's registries: 130-160 MB whatever the record) is
# a fixed cost, like the modules imported: every child loads it, through the compiled Allan
# kernel, before its baseline is taken, and prints its size.  A short record through
# ``allan_deviation`` would run the numpy reference and leave numba out of the baseline.
_WARM_UP = """
import gc
import numpy as np
def status(key):
    line = [x for x in open('/proc/self/status') if x.startswith(key)][0]
    return int(line.split()[1]) * 1024
before = status('VmRSS')
# (numba's registries load with the kernels' module)
from imu_allan.core.allan import kernel as allan_kernel
allan_kernel.avar(np.random.default_rng(0).normal(size=(20_000, 6)), np.array([1, 2, 10]))
gc.collect()
base = status('VmRSS')
runtime = base - before
"""

_CHILD = _WARM_UP + """
import sys
import imu_allan.formats.bag_reader, imu_allan.formats.csv_samples
from imu_allan.formats.readers import read_samples
base = status('VmRSS')
s = read_samples(sys.argv[1])
print(base, status('VmHWM'), s.t.nbytes + s.data.nbytes, runtime)
"""


# The whole ``analyze --json`` in a fresh process, measured the same way.
_ANALYZE = _WARM_UP + """
import contextlib, io, sys
from imu_allan.cli import analyze
import imu_allan.formats.bag_reader
base = status('VmRSS')
with contextlib.redirect_stdout(io.StringIO()):
    code = analyze.main([sys.argv[1], '--json'])
print(base, status('VmHWM'), code)
"""


def _analyze_peak(path):
    out = subprocess.run([sys.executable, '-c', _ANALYZE, str(path)], capture_output=True,
                         text=True, check=True).stdout.split()
    return [int(x) for x in out]


def _peak(path):
    out = subprocess.run([sys.executable, '-c', _CHILD, str(path)], capture_output=True,
                         text=True, check=True).stdout.split()
    return [int(x) for x in out]


def main():
    """Write the recordings, read each in its own process, print one line per format."""
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    n = int(hours * 3600 * 100)
    rng = np.random.default_rng(0)
    samples = Samples(t=1.7e9 + np.arange(n) / 100.0, data=rng.normal(0.0, 1e-3, (n, 6)))
    header('bench_memory')
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / 'rec.csv'
        write_csv(csv, samples)
        inputs = [('CSV', csv)]
        for storage in ('mcap', 'sqlite3', 'ros1'):
            out = Path(tmp) / ('rec.bag' if storage == 'ros1' else storage)
            inputs.append((storage, write_imu_bag(out, samples, storage=storage)))
        del samples
        for name, path in inputs:
            base, peak, decoded, runtime = _peak(path)
            size = sum(p.stat().st_size for p in ([path] if path.is_file()
                                                  else path.iterdir()))
            ratio = (peak - base) / decoded
            print(f'{name:7} {hours:g} h: file {size / 1e6:7.1f} MB, decoded '
                  f'{decoded / 1e6:6.1f} MB, peak RSS {peak / 1e6:7.1f} MB (baseline '
                  f'{base / 1e6:5.1f} MB, of which numba {runtime / 1e6:.0f} MB): '
                  f'{ratio:.2f}x decoded')
            goal(f'memory: reading {hours:g} h of {name}: {ratio:.2f}x the decoded size (goal '
                 '<= 1.5x)', ratio <= 1.5)
            if name in ('CSV', 'mcap', 'sqlite3'):
                base, peak, code = _analyze_peak(path)
                ratio = (peak - base) / decoded
                print(f'{name:7} {hours:g} h: analyze --json (exit {code}): peak RSS '
                      f'{peak / 1e6:7.1f} MB (baseline {base / 1e6:5.1f} MB): {ratio:.2f}x '
                      'decoded')
                goal(f'memory: analyze on {hours:g} h of {name}: {ratio:.2f}x the decoded size '
                     '(goal <= 1.5x)', ratio <= 1.5)


if __name__ == '__main__':
    main()
