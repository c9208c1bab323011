"""
The launch files, started with the real ``launch`` / ``launch_ros`` (Jazzy) libraries.

There is no ``ros2 launch`` without ros2cli, so a child process does what it does: a
``launch.LaunchService`` (it refuses to run outside a main thread) including the installed
launch file with its arguments, stopped with SIGINT.  ``make test`` builds the vendored launch
stack into the venv when no importable one exists (Makefile, ``launch-stack``).  Each test has
its own ROS_DOMAIN_ID and ROS_LOG_DIR; waits end on conditions, with generous timeouts.
"""

import importlib.util
import math
from pathlib import Path
import re
import signal
import subprocess
import sys
import time

from conftest import domain, executable, ros_env, spin_until
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

RUNNER = """
import os, signal, sys
# a signal disposition or mask inherited from the test process must not hide Ctrl-C
signal.pthread_sigmask(signal.SIG_UNBLOCK, [signal.SIGINT, signal.SIGTERM])
signal.signal(signal.SIGINT, signal.default_int_handler)
from ament_index_python.packages import get_package_share_directory
from launch import LaunchService
from launch.actions import IncludeLaunchDescription
from launch.launch_description_sources import PythonLaunchDescriptionSource
path = os.path.join(get_package_share_directory('imu_allan'), 'launch', sys.argv[1])
service = LaunchService()
service.include_launch_description(IncludeLaunchDescription(
    PythonLaunchDescriptionSource(path),
    launch_arguments=[arg.split(':=', 1) for arg in sys.argv[2:]]))
sys.exit(service.run())
"""
PARAMS = """/**/allan:
  ros__parameters:
    publish_period: 1.0
"""


@pytest.fixture(scope='module')
def launch_stack():
    """Skip (saying why) when launch_ros is not importable; ``make test`` provides it."""
    if importlib.util.find_spec('launch_ros') is None:
        pytest.skip('launch_ros not importable: run through make test (builds the vendored '
                    'Jazzy launch stack) or source a ROS 2 Jazzy install')


class Launch:
    """``ros2 launch imu_allan FILE ARGS`` in a child process, with its own domain and logs."""

    def __init__(self, tmp_path, domain, name, *args):
        env = ros_env(domain)
        env['ROS_LOG_DIR'] = str(tmp_path / 'ros_log')
        self.log = tmp_path / 'launch.log'
        self.proc = subprocess.Popen([sys.executable, '-c', RUNNER, name, *args], env=env,
                                     stdout=open(self.log, 'w'), stderr=subprocess.STDOUT)

    def stop(self):
        """SIGINT, as Ctrl-C on ``ros2 launch``; return the exit status and the output."""
        self.proc.send_signal(signal.SIGINT)
        try:
            status = self.proc.wait(60)  # generous: a loaded 2-core machine
        except subprocess.TimeoutExpired:
            self.proc.kill()
            status = self.proc.wait(10)
        return status, self.log.read_text()


def check_clean_shutdown(status, out, expected):
    """Exit 0, no traceback, every started process finished cleanly and is gone."""
    assert status == 0, out
    assert 'Traceback' not in out, out
    started = dict(re.findall(r'\[INFO\] \[(\w+)-\d+\]: process started with pid \[(\d+)\]',
                              out))
    assert sorted(started) == sorted(expected), out
    for name, pid in started.items():
        assert f'process has finished cleanly [pid {pid}]' in out, (name, out)
        assert not Path(f'/proc/{pid}').exists(), f'{name} (pid {pid}) still running'


@pytest.fixture
def ros_node(request):
    """Return an rclpy node and executor in their own context on the test's own domain id."""
    from rclpy.executors import SingleThreadedExecutor
    domain = request.param
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('launch_test_client', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    yield domain, node, executor
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def decode_coeffs(msg):
    """imu/allan_coeffs by its contract layout (docs/interfaces.md)."""
    dims = msg.layout.dim
    assert [(d.label, d.size, d.stride) for d in dims] == [('axis', 6, 90), ('term', 5, 15),
                                                           ('stat', 3, 3)]
    assert msg.layout.data_offset == 0
    return np.asarray(msg.data).reshape(6, 5, 3)


@pytest.mark.slow
@pytest.mark.parametrize('ros_node', [domain(2)], ids=['own_domain'], indirect=True)
def test_gx3_25_launch_against_the_simulator(launch_stack, ros_node, tmp_path):
    """gx3_sim -> gx3_25.launch.py (driver + allan + denoise) -> imu/allan_coeffs; SIGINT."""
    from std_msgs.msg import Float64MultiArray
    domain, node, executor = ros_node
    params = tmp_path / 'params.yaml'
    params.write_text(PARAMS)
    port = str(tmp_path / 'gx3')
    sim = subprocess.Popen([executable('gx3_sim'), '--link', port], stdout=subprocess.PIPE,
                           stderr=subprocess.DEVNULL, env=ros_env(domain))
    try:
        assert sim.stdout.readline().decode().strip() == port
        coeffs = []
        node.create_subscription(Float64MultiArray, 'imu/allan_coeffs', coeffs.append, 10)
        launch = Launch(tmp_path, domain, 'gx3_25.launch.py', f'port:={port}',
                        'rate_hz:=100.0', f'params_file:={params}')
        try:
            assert spin_until(executor, lambda: coeffs, 120), launch.log.read_text()
        finally:
            status, out = launch.stop()  # the driver goes before the simulator
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)
    table = decode_coeffs(coeffs[-1])
    assert np.isfinite(table[:, 1, 0]).sum() >= 3, table[:, 1]  # white noise, several axes
    check_clean_shutdown(status, out, ['driver', 'allan', 'denoise'])


@pytest.mark.slow
@pytest.mark.parametrize('ros_node', [domain(3)], ids=['own_domain'], indirect=True)
def test_monitor_launch_on_any_imu_topic(launch_stack, ros_node, tmp_path):
    """
    Run monitor.launch.py imu_topic:=/test_imu/data namespace:=mon.

    Both nodes on that topic, outputs under /mon, the rate measured from the stamps (no
    rate_hz given).
    """
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray
    domain, node, executor = ros_node
    params = tmp_path / 'params.yaml'
    params.write_text(PARAMS)
    coeffs, denoised = [], []
    node.create_subscription(Float64MultiArray, '/mon/imu/allan_coeffs', coeffs.append, 10)
    node.create_subscription(Imu, '/mon/imu/data_denoised', denoised.append,
                             qos_profile_sensor_data)
    pub = node.create_publisher(Imu, '/test_imu/data', 1000)
    launch = Launch(tmp_path, domain, 'monitor.launch.py', 'imu_topic:=/test_imu/data',
                    'namespace:=mon', f'params_file:={params}')
    rng = np.random.default_rng(2)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() >= 2, 60), \
            launch.log.read_text()
        t0, sent = 1_700_000_000.0, 0
        end = time.monotonic() + 120
        while not (coeffs and denoised) and time.monotonic() < end:
            for _ in range(100):  # 200 Hz stamps, sent faster than real time
                msg = Imu()
                ti = t0 + sent / 200.0
                msg.header.stamp.sec = int(math.floor(ti))
                msg.header.stamp.nanosec = int(round((ti - math.floor(ti)) * 1e9))
                w, a = msg.angular_velocity, msg.linear_acceleration
                w.x, w.y, w.z = rng.normal(0.0, 1e-3, 3)
                a.x, a.y, a.z = rng.normal(0.0, 1e-2, 3) + (0.0, 0.0, 9.80665)
                pub.publish(msg)
                sent += 1
            executor.spin_once(timeout_sec=0.05)
    finally:
        status, out = launch.stop()
    assert coeffs and denoised, out
    assert np.isfinite(decode_coeffs(coeffs[-1])[:, 1, 0]).all()
    assert re.search(r'sample rate 19\d\.\d+ Hz \(measured\)|sample rate 200 Hz \(measured\)',
                     out), out
    check_clean_shutdown(status, out, ['allan', 'denoise'])
