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
#: This test process's own ROS_DOMAIN_ID: DDS tests in parallel processes see each other.
DOMAIN = os.getpid() % 100 + 100
EXECUTABLES = ('driver', 'allan', 'denoise', 'analyze', 'discrepancy', 'gx3_sim', 'monitor',
               'fleet')


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
