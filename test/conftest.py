"""Shared test fixtures: paths, the built install tree, per-process ROS domain ids."""

import os
from pathlib import Path
import subprocess
import sys

import pytest

# Single-threaded BLAS, as the nodes and commands set it (nodes/__init__.py): on this shared
# 2-core machine a threaded 40x40 triangular solve took 3 ms instead of 0.17 ms, which made the
# fit-heavy tests ~10x slower.  Set before any test module imports numpy.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

REPO = Path(__file__).resolve().parents[1]
#: The shared folder beside the repository (CI: a fresh clone with shared/ next to it); a
#: checkout elsewhere names it with IMU_ALLAN_SHARED.
SHARED = Path(os.environ.get('IMU_ALLAN_SHARED', REPO.parent / 'shared'))
SHARED_DATA = SHARED / 'data'
#: ROS_DOMAIN_IDs 100-199 in blocks of this many, one block per test process.
DOMAINS_PER_PROCESS = 4


def _domain_block():
    """
    Return the first ROS_DOMAIN_ID of this test process's block (one block per process).

    DDS tests in parallel processes would see each other's nodes on a shared domain.  Under
    pytest-xdist each worker is a process of its own: the workers of one run take consecutive
    blocks by their number (``PYTEST_XDIST_WORKER`` gw0, gw1, ...) from a place drawn from the
    run's id, so two workers of a run never share a domain (a pid-based id did, for pids equal
    modulo 100).  Without xdist the pid draws the place; another run on the same machine
    shares a block by chance only (1 in 25 per pair of processes).
    """
    blocks = 100 // DOMAINS_PER_PROCESS
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    run = os.environ.get('PYTEST_XDIST_TESTRUNUID')
    base = int(run, 16) if run else os.getpid()
    index = int(worker[2:]) if worker.startswith('gw') and worker[2:].isdigit() else 0
    return 100 + (base + index) % blocks * DOMAINS_PER_PROCESS


#: This test process's own ROS_DOMAIN_ID (the first of its block; :func:`domain` gives the rest).
DOMAIN = _domain_block()


def domain(k):
    """Return this process's ``k``-th ROS_DOMAIN_ID (0 = :data:`DOMAIN`), for a module's own."""
    if not 0 <= k < DOMAINS_PER_PROCESS:
        raise ValueError(f'domain {k}: a test process has {DOMAINS_PER_PROCESS}')
    return DOMAIN + k


EXECUTABLES = ('driver', 'allan', 'denoise', 'analyze', 'discrepancy', 'gx3_sim', 'monitor',
               'fleet')


def pytest_configure(config):
    """
    Under pytest-xdist, in the controller: compile the numba kernels once while workers collect.

    Without it two workers asking for the same uncached kernel (a fresh install, or a kernel's
    file changed) both compile it.  numba's cache writes are atomic (temporary file, then
    rename), so that is safe but wasted; and two processes saving two new type signatures of
    one function at the same moment can both take the same data file name (numba reads, adds
    and rewrites the index without a lock).  ``warm_kernels.py`` compiles the package's usual
    signatures first, in one process (with a warm cache it only loads them: about as long as
    importing numba, well inside the workers' collection).
    """
    if getattr(config.option, 'numprocesses', None) and not hasattr(config, 'workerinput'):
        config.imu_allan_warm = subprocess.Popen(
            [sys.executable, str(Path(__file__).with_name('warm_kernels.py'))],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node, ids):
    """Hand out no test before the kernels are compiled (the controller waits here)."""
    warm = getattr(node.config, 'imu_allan_warm', None)
    if warm is not None:
        warm.wait()


def pytest_unconfigure(config):
    """Never leave the warm-up running (a run stopped before collection ended)."""
    warm = getattr(config, 'imu_allan_warm', None)
    if warm is not None and warm.poll() is None:
        warm.kill()
        warm.wait()


@pytest.fixture(scope='session')
def shared_data():
    """Return the third-party test data folder (tests skip when it is absent)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f'{SHARED_DATA} not present (shared test data)')
    return SHARED_DATA


def executable(name):
    """Path of a built executable, found the way ``ros2 run imu_allan NAME`` finds it."""
    from ament_index_python.packages import get_package_prefix
    prefix = get_package_prefix('imu_allan')
    path = os.path.join(prefix, 'lib', 'imu_allan', name)
    if not (os.path.isfile(path) and os.access(path, os.X_OK)):
        raise FileNotFoundError(f'No executable found: {path}')
    return path


def run_command(name, *args, timeout=120, env=None, **kwargs):
    """Run a built executable and capture its output (text)."""
    return subprocess.run([executable(name), *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, env=env, **kwargs)


def ros_env(domain=None):
    """Environment for a DDS subprocess with its own ROS_DOMAIN_ID."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain if domain is not None else DOMAIN)
    env.setdefault('PYTHONUNBUFFERED', '1')
    return env


@pytest.fixture(scope='module')
def ros_context():
    """Return an rclpy context on this process's own domain id (:data:`DOMAIN`)."""
    rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')
    os.environ['ROS_DOMAIN_ID'] = str(DOMAIN)
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


def python():
    """Return the interpreter running the tests (the venv's)."""
    return sys.executable


def spin_until(executor, predicate, timeout):
    """Spin an rclpy executor until ``predicate()`` is true; False after ``timeout`` s."""
    import time
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.05)
        if predicate():
            return True
    return False


class NodeRun:
    """
    A built node in its own process and a client node spinning here (a context manager).

    ``with NodeRun(cmd, context, 'client') as run:`` gives ``run.node`` and ``run.executor``;
    on leaving, the client is shut down, the node stopped (``stop_signal``, then killed after
    10 s) and ``run.output`` holds its stdout and stderr.  ``shutdown_context`` also shuts the
    rclpy context down (for tests that made their own).
    """

    def __init__(self, cmd, context, client, domain=None, stop_signal=None,
                 shutdown_context=False):
        """Keep the command and the rclpy context; nothing starts before ``with``."""
        self.cmd, self.context, self.client = cmd, context, client
        self.domain, self.stop_signal = domain, stop_signal
        self.shutdown_context = shutdown_context
        self.output = ''

    def __enter__(self):
        """Start the node process and the client node with its executor."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self.proc = subprocess.Popen(self.cmd, env=ros_env(self.domain), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True)
        self.node = rclpy.create_node(self.client, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc):
        """Stop the client, then the node; keep its output."""
        import rclpy
        self.executor.shutdown()
        self.node.destroy_node()
        if self.shutdown_context:
            rclpy.try_shutdown(context=self.context)
        if self.stop_signal is None:
            self.proc.terminate()
        else:
            self.proc.send_signal(self.stop_signal)
        try:
            self.output, _ = self.proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.output, _ = self.proc.communicate()
        return False
