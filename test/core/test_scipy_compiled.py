"""scipy's compiled routines, loaded without their subpackages, equal the public ones."""

import subprocess
import sys

from imu_allan.core import scipy_compiled
from imu_allan.core.allan.edf import chi2_interval
import numpy as np
import pytest
import scipy.special


def test_the_fits_and_intervals_import_neither_scipy_optimize_nor_scipy_special():
    """The point of the module: the 0.6 s of those imports is not paid by ``analyze``."""
    code = ('import sys; import imu_allan.core.analysis, imu_allan.core.fit.advisor; '
            'from imu_allan.core.allan import edf; from imu_allan.core.fit import nnls; '
            'assert nnls._compiled_nnls is not None; '
            'print(sorted(m for m in sys.modules if m.startswith("scipy")))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    # only the two compiled modules, under their names, not the packages around them
    assert out.strip() == "['scipy.optimize._slsqplib', 'scipy.special._special_ufuncs']"


def test_inverse_gamma_gives_scipy_chi_square_quantiles_bit_for_bit():
    rng = np.random.default_rng(0)
    k = np.concatenate([10.0 ** rng.uniform(-0.5, 7.5, 5000), np.arange(1.0, 200.0)])
    q = rng.uniform(0.0, 1.0, k.size)
    inverse = scipy_compiled.function('special', '_special_ufuncs', 'gammainccinv')
    assert np.array_equal(2.0 * inverse(0.5 * k, q), scipy.special.chdtri(k, q))
    low, high = chi2_interval(np.ones(k.size), k)
    p = (1.0 - 0.6826894921370859) / 2.0
    assert np.array_equal(low, np.sqrt(k / scipy.special.chdtri(k, p)))
    assert np.array_equal(high, np.sqrt(k / scipy.special.chdtri(k, 1.0 - p)))


def test_missing_module_falls_back_to_the_public_function():
    assert scipy_compiled.extension('special', 'no_such_module') is None
    assert scipy_compiled.function('special', 'no_such_module', 'gammainccinv') is \
        scipy.special.gammainccinv


def test_numba_kernels_load_without_importing_scipy_linalg():
    """The BLAS probe of numba is served without scipy.linalg, which imports normally later."""
    code = ('import sys; import numpy as np; '
            'from imu_allan.core.allan import kernel as allan_kernel; '
            'allan_kernel.column_means(np.ones((8, 2))); '
            'assert "scipy.linalg" not in sys.modules, "the probe imported scipy.linalg"; '
            'import scipy.linalg; '
            'assert scipy.linalg.cython_blas is sys.modules["scipy.linalg.cython_blas"]; '
            'print(scipy.linalg.solve(np.eye(2), np.ones(2)))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['[1.', '1.]']


@pytest.mark.parametrize('measuring', [False, True])
def test_numba_imported_without_coverage_unless_measuring(measuring):
    """
    The kernels import numba without ``coverage``; a process measuring coverage keeps it.

    (colcon's pytest-cov installs coverage; this environment has it, the test needs it.)
    """
    pytest.importorskip('coverage')
    code = ('import sys; ' + ('import coverage; ' if measuring else '')
            + 'from imu_allan.core import jit; '
            'from numba.misc import coverage_support as c; '
            'print(c.coverage_available, "coverage" in sys.modules); '
            'import coverage; print(coverage.Coverage.current())')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == [str(measuring), str(measuring), 'None']
