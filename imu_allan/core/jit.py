"""
numba's ``njit`` with the disk cache: how every compiled kernel of the package is made.

Compiled once per install: the kernels are module-level functions with ``cache=True``, which
numba keys by their file and names, so the machine code compiled by the first process is
loaded by every later one.  (Functions defined inside another function never hit that cache:
their closure is part of the key and differs in every process.)  Where the package's
``__pycache__`` cannot be written (a read-only install), numba falls back to the user cache
directory (``~/.cache/numba``, or ``$NUMBA_CACHE_DIR`` when set); where no directory is
writable at all, :func:`jit` compiles without the cache and lists the kernel in
:data:`UNCACHED`, so that its module can say so or decline to use it.

Imported only by the kernel modules (:mod:`.allan.kernel`, :mod:`..formats.bag_kernels`),
themselves imported on first use: numba is optional and costs about 1 s to load.

Before the first kernel runs, even from the cache, numba loads its typing registries, and one
of them probes for BLAS with ``import scipy.linalg.cython_blas``: that imports all of
``scipy.linalg`` (0.2-0.4 s here), which no kernel here uses.  So the registries are loaded
here, with that one compiled module loaded on its own (:mod:`.scipy_compiled`) for the probe
to find, and taken out of ``sys.modules`` again: a later ``import scipy.linalg`` loads it as
usual.  numba is imported without ``coverage`` for the same reason (:func:`_import_numba`).
"""

from concurrent.futures import ThreadPoolExecutor
import os
import sys

from .scipy_compiled import extension


def _import_numba():
    """
    Import numba without ``coverage`` unless this process already measures coverage.

    numba imports ``coverage`` (60-150 ms here) whenever it is installed, to report the lines
    of compiled functions to a measurement started later; colcon's pytest-cov installs it on
    every ROS development machine.  A process measuring coverage imports it before numba, and
    then numba finds it as usual.
    """
    blocked = 'coverage' not in sys.modules
    if blocked:
        sys.modules['coverage'] = None  # makes ``import coverage`` raise ImportError
    try:
        import numba
    finally:
        if blocked and sys.modules.get('coverage', 0) is None:
            del sys.modules['coverage']
    return numba


numba = _import_numba()


def _load_registries():
    name = 'scipy.linalg.cython_blas'
    blas = None if name in sys.modules else extension('linalg', 'cython_blas')
    try:
        numba.core.registry.cpu_target.target_context.refresh()
    except AttributeError:  # another numba layout: the first kernel call loads them
        pass
    finally:
        if blas is not None and sys.modules.get(name) is blas:
            del sys.modules[name]


_load_registries()

#: Names of the kernels compiled without a disk cache (no writable cache directory).
UNCACHED = []


_POOL = []


def map_threads(fn, jobs):
    """
    Run ``fn`` over ``jobs`` on one thread per core (inline on a single core); return results.

    For kernels compiled with ``nogil=True``: one pool for the whole process, so kernels
    called from several threads at once share the cores instead of each starting its own.
    """
    workers = len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else 1
    if workers < 2 or len(jobs) < 2:
        return [fn(job) for job in jobs]
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(workers, thread_name_prefix='imu_allan_kernel'))
    return list(_POOL[0].map(fn, jobs))


def jit(**options):
    """Compile with numba, cached on disk (``cache=True``); uncached if nothing is writable."""
    def wrap(fn):
        try:
            return numba.njit(cache=True, **options)(fn)
        except RuntimeError:  # numba: "cannot cache function ...: no locator available"
            UNCACHED.append(fn.__name__)
            return numba.njit(**options)(fn)
    return wrap
