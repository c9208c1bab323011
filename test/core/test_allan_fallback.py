"""
numba is optional: without it the numpy reference estimator gives the same numbers.

The child process blocks the import (``sys.modules['numba'] = None`` makes ``import numba``
raise ImportError, as on a platform with no numba package) and asks twice for the compiled
path (``avar_fast``; long records choose it by themselves), printing the results; this process
computes the same with numba.  Tukey's quartiles, asked of the compiled path too, come from
numpy.
"""

import json
import subprocess
import sys

from imu_allan.core.allan.estimate import avar_fast, tau_grid
import numpy as np

CHILD = """
import json, sys
sys.modules['numba'] = None
import numpy as np
from imu_allan.core.allan.estimate import avar_fast, tau_grid
data = np.random.default_rng(3).normal(size=(20000, 3))
first = avar_fast(data, tau_grid(20000))
second = avar_fast(data[:5000], tau_grid(5000))   # the log line comes once, not per call
from imu_allan.core.checks import preprocess
preprocess.KERNEL_ROWS = 0                          # Tukey's quartiles: numpy without numba
quart = preprocess.quartiles(data)
print(json.dumps([first.tolist(), second.tolist(), quart.tolist()]))
"""


def test_without_numba_same_numbers_and_one_log_line():
    """
    Without numba: the same AVAR, and one log line naming numba and what to install.

    Same within float rounding (the compiled kernel sums in another order, fastmath).
    """
    out = subprocess.run([sys.executable, '-c', CHILD], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    first, second, quart = (np.array(a) for a in json.loads(out.stdout))
    data = np.random.default_rng(3).normal(size=(20000, 3))
    np.testing.assert_allclose(first, avar_fast(data, tau_grid(20000)), rtol=1e-9)
    np.testing.assert_allclose(second, avar_fast(data[:5000], tau_grid(5000)), rtol=1e-9)
    np.testing.assert_array_equal(quart, np.percentile(data, [25, 75], axis=0).T)
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert 'numba is not installed' in lines[0] and 'pip install numba' in lines[0]
