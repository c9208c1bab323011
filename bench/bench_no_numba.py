"""
Allan deviation with and without numba (the optional dependency): how much slower.

The thesis's largest data set size (1.7 M samples x 6 axes, 4.7 h at 100 Hz), default grid;
the no-numba run is a child process with ``import numba`` blocked, as on a platform that does
not package numba.  Prints both times and the ratio (docs/benchmarks.md).
"""

import os
import subprocess
import sys
import time

CODE = """
import sys, time
if sys.argv[1] == 'off':
    sys.modules['numba'] = None
from imu_allan.core.allan.estimate import allan_deviation
data = np.random.default_rng(1).normal(size=(1_700_000, 6))
allan_deviation(data[:1000], 100.0)   # compile / load the kernel, log the fallback once
best = min((lambda t0: (allan_deviation(data, 100.0), time.perf_counter() - t0)[1])(
    time.perf_counter()) for _ in range(3))
print(best)
"""


def run(mode):
    """Best of three, in s, of one allan_deviation on the data set; numba 'on' or 'off'."""
    out = subprocess.run([sys.executable, '-c', CODE, mode], capture_output=True, text=True,
                         check=True, env=dict(os.environ))
    return float(out.stdout.strip())


def main():
    """Print both times and the slowdown."""
    start = time.perf_counter()
    with_numba, without = run('on'), run('off')
    print(f'allan_deviation, 1.7 M x 6 samples: numba {with_numba:.2f} s, numpy reference '
          f'{without:.2f} s: {without / with_numba:.1f}x slower without numba '
          f'(bench {time.perf_counter() - start:.0f} s)')


if __name__ == '__main__':
    main()
