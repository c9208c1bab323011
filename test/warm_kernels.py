"""
Compile (or load) the package's numba kernels once, in one process, before the tests use them.

Run by ``test/conftest.py`` in the pytest-xdist controller while the workers collect: numba's
disk cache then holds every kernel before a test asks for one, so on a fresh install (CI) or
after a kernel's file changed each kernel is compiled once instead of once per worker (two
workers asking for the same uncached kernel both compile it; the cache's writes are atomic, so
that is only wasted time).  With a warm cache this loads the kernels and takes about as long as
importing numba.

The kernels run on tiny inputs through the package's own entry points, with the size
thresholds that keep short inputs on numpy set to zero: the compiled specialisations are those
of the package's usual arrays (float64, C order), whatever their length.  Anything that fails
here is left to the tests (they compile what they need).
"""

import sys
import tempfile

import numpy as np


def main():
    """Call every compiled path once; return 0 (what could not run is the tests' to find)."""
    try:
        from imu_allan.core import jit  # noqa: F401  (numba present)
        from imu_allan.core.allan import estimate as allan
        from imu_allan.core.checks import preprocess
    except ImportError:  # no numba: nothing to compile
        return 0
    from imu_allan.core.deviations import deviation, KINDS
    from imu_allan.formats import mcap_scan, sqlite_pages
    from imu_allan.formats.bag_reader import read_bag
    from imu_allan.formats.bag_writer import write_imu_bag
    from imu_allan.formats.samples import Samples

    allan.SMALL_WORK = 0
    preprocess.KERNEL_ROWS = 0
    sqlite_pages.COMPILED_MIN_PAGES = 0
    mcap_scan.COMPILED_MIN_BYTES = 0
    data = np.random.default_rng(0).normal(size=(500, 6))  # mtotdev of 4000: 10 s
    allan.allan_deviation(data, 100.0)
    for kind in KINDS:
        deviation(data, 100.0, kind)
    preprocess.quartiles(data)
    with tempfile.TemporaryDirectory(prefix='imu_allan_warm_') as tmp:
        for storage in ('sqlite3', 'mcap'):
            path = f'{tmp}/bag_{storage}'
            write_imu_bag(path, Samples(t=1.7e9 + np.arange(500) / 100.0, data=data),
                          storage=storage)
            read_bag(path)
    return 0


if __name__ == '__main__':
    sys.exit(main())
