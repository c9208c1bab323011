"""
Benchmark: peak memory of reading a long recording (CSV and MCAP) against its decoded size.

Writes HOURS of 100 Hz six-axis samples as a contract CSV and as an MCAP rosbag2 into a
temporary folder, then reads each in a fresh process (``read_samples``, what ``analyze`` does
first) and prints the peak resident set size (``VmHWM``), the decoded arrays' size (t and
data, float64) and the peak above the interpreter's own baseline (numpy and the readers
imported, nothing read) divided by the decoded size. Goal: at most 1.5x.
Usage: ``python bench/bench_memory.py [HOURS]`` (default 2; the issue's case is 10).
"""

from pathlib import Path
import subprocess
import sys
import tempfile

from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
import numpy as np

_CHILD = """
import sys
import imu_allan.formats.bag_reader, imu_allan.formats.csv_samples
from imu_allan.formats.readers import read_samples
def hwm():  # peak RSS of this process image (VmHWM; ru_maxrss would include the parent's)
    line = [x for x in open('/proc/self/status') if x.startswith('VmHWM')][0]
    return int(line.split()[1]) * 1024
base = hwm()
s = read_samples(sys.argv[1])
print(base, hwm(), s.t.nbytes + s.data.nbytes)
"""


def _peak(path):
    out = subprocess.run([sys.executable, '-c', _CHILD, str(path)], capture_output=True,
                         text=True, check=True).stdout.split()
    return [int(x) for x in out]


def main():
    """Write the recordings, read each in its own process, print one line per format."""
    hours = float(sys.argv[1]) if len(sys.argv) > 1 else 2.0
    n = int(hours * 3600 * 100)
    rng = np.random.default_rng(0)
    samples = Samples(t=1.7e9 + np.arange(n) / 100.0, data=rng.normal(0.0, 1e-3, (n, 6)))
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / 'rec.csv'
        write_csv(csv, samples)
        bag = write_imu_bag(Path(tmp) / 'bag', samples, storage='mcap')
        del samples
        for name, path in (('CSV', csv), ('MCAP', bag)):
            base, peak, decoded = _peak(path)
            size = sum(p.stat().st_size for p in ([path] if path.is_file()
                                                  else path.iterdir()))
            print(f'{name:5} {hours:g} h: file {size / 1e6:7.1f} MB, decoded {decoded / 1e6:6.1f}'
                  f' MB, peak RSS {peak / 1e6:7.1f} MB (baseline {base / 1e6:5.1f} MB): '
                  f'{(peak - base) / decoded:.2f}x decoded')


if __name__ == '__main__':
    main()
