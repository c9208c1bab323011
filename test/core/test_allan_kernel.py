"""
Tests of the compiled AVAR kernel (imu_allan/core/allan/kernel.py).

Every fast path is compared with the numpy reference (``allan.avar_reference``, ``allan._phase``)
on shapes that reach its edges: odd lengths, block boundaries, m near n / 2, groups of four
averaging times with a remainder, one axis and many axes.  The cache tests run fresh
interpreters (a compile there takes a few seconds; the second process of each pair about one).
"""

import os
from pathlib import Path
import shutil
import subprocess
import sys

from imu_allan.core import jit, scipy_compiled
from imu_allan.core.allan import kernel as allan_kernel
from imu_allan.core.allan.estimate import _phase, avar_reference
import numpy as np
import pytest

# Cases (samples, axes, averaging factors): chosen to cross the kernel's branches.
_N_BLOCK = allan_kernel.BLOCK


@pytest.mark.parametrize('n, axes, ms', [
    (2, 1, [1]),                                       # the shortest record
    (7, 1, [3, 1, 2]),                                 # unsorted, m = (n - 1) / 2
    (1001, 3, list(range(1, 501, 7)) + [500]),         # m = n / 2 (one second difference)
    (3 * _N_BLOCK + 5, 6, [1, 2, 3, 5, 8, 13, 21]),    # a remainder group of three
    (_N_BLOCK + 1, 9, list(range(1, 41))),             # many axes, whole groups of four
    (40_000, 1, np.unique(np.geomspace(1, 20_000, 60).astype(int)).tolist()),  # one axis
])
def test_fast_avar_equals_reference(n, axes, ms):
    """
    Same AVAR as the numpy reference to 1e-9 relative.

    Both sum the same exact terms; only the rounding order differs (~1e-13 here).
    """
    rng = np.random.default_rng(n)
    data = rng.normal(size=(n, axes)) * 0.01 + 9.8   # a large mean, as accelerometers have
    fast = allan_kernel.avar(data, np.array(ms))
    ref = avar_reference(data, np.array(ms))
    assert fast.shape == (len(ms), axes)
    np.testing.assert_allclose(fast, ref, rtol=1e-9, atol=0)


def test_fast_phase_equals_reference():
    """
    The compiled phase equals the numpy cumulative sum to rounding.

    Two ranges of rows are integrated in parallel, then joined.  The result equals the reference
    up to a drift k * delta from the mean's rounding (summed in another order; |delta| < 1e-14
    x the mean) and a rounding noise of 1e-13 of the largest phase value (measured ~1e-15).
    The drift cancels in every second difference; a join carrying the column sums' rounding
    had left a 1e-9 step, which does not.
    """
    data = np.random.default_rng(3).normal(size=(40_001, 6)) * 0.01 + [0, 0, 0, 0, 0, 9.8]
    ref = _phase(data)
    diff = allan_kernel.phase(data) - ref
    k = np.arange(ref.shape[1])
    delta = diff[:, -1] / k[-1]
    assert np.all(np.abs(delta) <= 1e-14 * (np.abs(data.mean(axis=0)) + 1e-3))
    np.testing.assert_allclose(diff - delta[:, None] * k, 0.0, rtol=0,
                               atol=1e-13 * np.abs(ref).max())


def test_bad_averaging_factors_are_refused():
    data = np.zeros((10, 1))
    with pytest.raises(ValueError, match='1 .. 5'):
        allan_kernel.avar(data, np.array([6]))
    with pytest.raises(ValueError):
        allan_kernel.avar(data, np.array([0]))


_SCRIPT = """
import sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from kernels.allan import kernel as allan_kernel
d = np.random.default_rng(0).normal(size=(5000, 2))
ms = np.array([1, 2, 3, 5, 8, 13, 21, 34, 55])
print(float(allan_kernel.avar(d, ms)[0, 0]))
"""


def _run(folder, env):
    proc = subprocess.run([sys.executable, '-c', _SCRIPT, str(folder.parent.parent)], env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc


def _snapshot(folder):
    return {p: p.stat().st_mtime_ns for p in Path(folder).rglob('*') if p.is_file()}


def _env(tmp_path, **extra):
    env = {k: v for k, v in os.environ.items() if not k.startswith('NUMBA_')}
    env.update(HOME=str(tmp_path / 'home'), XDG_CACHE_HOME=str(tmp_path / 'cache'),
               NUMBA_DEBUG_CACHE='1', **extra)
    return env


def _module_copy(tmp_path):
    """
    Copy the kernel module into a fresh package ``kernels`` (own source: own cache entries).

    The package has the installed one's shape (``kernels/allan/kernel.py`` beside
    ``kernels/jit.py``: the kernel's relative imports).  Return the kernel's folder; the
    package's parent goes on ``sys.path``.
    """
    package = tmp_path / 'pkg' / 'kernels'
    folder = package / 'allan'
    folder.mkdir(parents=True)
    for init in (package, folder):
        (init / '__init__.py').write_text('')
    shutil.copy(allan_kernel.__file__, folder / 'kernel.py')
    for module in (jit, scipy_compiled):
        shutil.copy(module.__file__, package / Path(module.__file__).name)
    return folder


@pytest.mark.slow
def test_second_process_compiles_nothing(tmp_path):
    """
    A second process compiles nothing.

    With a fresh NUMBA_CACHE_DIR the first process saves the compiled kernel; the second loads
    it and saves no new entry (numba's NUMBA_DEBUG_CACHE lines and the folder agree).
    Budget: one compile (2-5 s) and one load (~1 s).
    """
    folder, cache = _module_copy(tmp_path), tmp_path / 'numba_cache'
    env = _env(tmp_path, NUMBA_CACHE_DIR=str(cache))
    first = _run(folder, env)
    assert 'data saved to' in first.stdout + first.stderr
    before = _snapshot(cache)
    assert any(p.suffix == '.nbc' for p in before)
    second = _run(folder, env)
    log = second.stdout + second.stderr
    assert 'saved to' not in log and 'data loaded from' in log
    assert _snapshot(cache) == before
    assert second.stdout.splitlines()[-1] == first.stdout.splitlines()[-1]
    assert 'Allan kernel' not in first.stderr     # the user chose the folder: nothing to say


@pytest.mark.slow
def test_read_only_install_caches_in_user_folder_and_says_so(tmp_path):
    """
    A read-only install caches the kernel in the user cache folder.

    Where the module's __pycache__ cannot be created (here a file is in its place, which
    also stops root), the kernel is cached in the user cache folder, the first process says so
    in one line, and the second finds it there and compiles nothing.  Budget as above.
    """
    folder = _module_copy(tmp_path)
    (folder / '__pycache__').write_text('not a folder')
    env = _env(tmp_path)
    first = _run(folder, env)
    notes = [line for line in first.stderr.splitlines() if 'Allan kernel' in line]
    assert len(notes) == 1 and str(tmp_path / 'cache' / 'numba') in notes[0], first.stderr
    assert any((tmp_path / 'cache' / 'numba').rglob('*.nbc'))
    second = _run(folder, env)
    assert 'saved to' not in second.stdout + second.stderr
    assert 'Allan kernel' not in second.stderr


_WALK_SCRIPT = """
import sys
from imu_allan.formats import sqlite_pages
from imu_allan.formats.bag_reader import read_bag
sqlite_pages.COMPILED_MIN_PAGES = 0   # the compiled sqlite3 page walk even for a small bag
r = read_bag(sys.argv[1])
print(r.n, float(r.data.sum()))
"""


@pytest.mark.slow
def test_sqlite_walk_second_process_compiles_nothing(tmp_path):
    """
    The compiled sqlite3 page walk (imu_allan.formats.bag_kernels) is compiled once too.

    Same check as above on the installed module: the first process reading a sqlite3 bag saves
    the walk into a fresh NUMBA_CACHE_DIR, the second loads it and saves nothing.  Budget: one
    compile (5-10 s) and one load (~1 s).
    """
    from imu_allan.formats.bag_writer import write_imu_bag
    from imu_allan.formats.samples import Samples
    bag = tmp_path / 'bag'
    data = np.random.default_rng(2).normal(size=(300, 6))
    write_imu_bag(bag, Samples(t=1.7e9 + np.arange(300) / 100.0, data=data), storage='sqlite3')
    first, second = _twice(tmp_path, [_WALK_SCRIPT, str(bag)], 'bag_kernels',
                           ['sqlite_walk'])
    assert second.stdout.splitlines()[-1] == first.stdout.splitlines()[-1] == \
        f'300 {float(data.sum())}'


def _twice(tmp_path, args, module, kernels):
    """
    Run ``python -c *args`` twice with a fresh NUMBA_CACHE_DIR; return both processes.

    Asserts that the first saved each of ``kernels`` of ``module`` and the second saved nothing.
    """
    cache = tmp_path / 'numba_cache'
    env = _env(tmp_path, NUMBA_CACHE_DIR=str(cache))
    runs = []
    for _ in range(2):
        proc = subprocess.run([sys.executable, '-c', *args], env=env, capture_output=True,
                              text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        runs.append((proc, _snapshot(cache)))
    (first, before), (second, after) = runs
    saved = [line for line in (first.stdout + first.stderr).splitlines()
             if 'data saved to' in line]
    for kernel in kernels:
        assert any(module in line and kernel in line for line in saved), (kernel, saved)
    log = second.stdout + second.stderr
    assert 'saved to' not in log and 'data loaded from' in log
    assert after == before
    return first, second


_QUARTILE_SCRIPT = """
import numpy as np
from imu_allan.core.checks import preprocess
preprocess.KERNEL_ROWS = 0   # the compiled order statistics even for a short record
data = np.random.default_rng(4).normal(size=(2000, 6))
data[10, 3] = 99.0
_, report = preprocess.replace_outliers(data, 'abcdef', replace=False)
print(report.counts, preprocess.quartiles(data).tolist())
"""


@pytest.mark.slow
def test_quantile_kernels_second_process_compile_nothing(tmp_path):
    """
    The compiled order statistics (imu_allan.core.checks.quantile_kernel) are compiled once too.

    Budget: one compile (about 3 s) and one load.
    """
    first, second = _twice(tmp_path, [_QUARTILE_SCRIPT], 'quantile_kernel',
                           ['order_stats', 'outside'])
    result = first.stdout.splitlines()[-1]
    assert second.stdout.splitlines()[-1] == result and "'d': 1" in result
