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
