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
import os
from pathlib import Path
import re
import signal
import subprocess
import sys
import time
from types import ModuleType, SimpleNamespace

from ament_index_python.packages import get_package_share_directory
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
    # the 90 numbers the dims describe; each axis's adequacy p follows (6 more), then the
    # 30 upper limits of the terms not resolved
    assert len(msg.data) == 126
    return np.asarray(msg.data[:90]).reshape(6, 5, 3)


class Recorded:
    """Stand-in for a launch class: keeps the arguments it was built with."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


STAND_INS = {'launch': ['LaunchDescription'],
             'launch.actions': ['DeclareLaunchArgument', 'IncludeLaunchDescription',
                                'OpaqueFunction'],
             'launch.launch_description_sources': ['PythonLaunchDescriptionSource'],
             'launch.substitutions': ['LaunchConfiguration'],
             'launch_ros': [], 'launch_ros.actions': ['Node']}


def expand(name_or_path, arguments):
    """
    ``{node name: Node keyword arguments}`` a launch file starts for ``arguments``.

    Its arguments' defaults, updated with ``arguments``, go to its OpaqueFunctions; includes
    are expanded the same way with their launch_arguments.  Needs the launch stand-ins.
    """
    path = name_or_path if os.sep in name_or_path else os.path.join(
        get_package_share_directory('imu_allan'), 'launch', name_or_path)
    spec = importlib.util.spec_from_file_location('launch_file_under_test', path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    entities = module.generate_launch_description().args[0]
    config = {e.args[0]: e.kwargs['default_value'] for e in entities
              if type(e).__name__ == 'DeclareLaunchArgument'}
    config.update(arguments)
    context = SimpleNamespace(launch_configurations=config)
    nodes = {}
    for entity in entities:
        if type(entity).__name__ != 'OpaqueFunction':
            continue
        for out in entity.kwargs['function'](context):
            if type(out).__name__ == 'Node':
                nodes[out.kwargs['name']] = out.kwargs
            else:  # IncludeLaunchDescription(PythonLaunchDescriptionSource(path), ...)
                nodes.update(expand(out.args[0].args[0], dict(out.kwargs['launch_arguments'])))
    return nodes


def given(node, name):
    """Return the value a node's parameter dicts give ``name`` (the last one wins), or None."""
    values = [p[name] for p in node['parameters'] if isinstance(p, dict) and name in p]
    return values[-1] if values else None


def test_gx3_25_launch_gives_allan_the_drivers_filter_window(monkeypatch):
    """
    filter_window reaches the driver (taps) and the allan node (filter_window_s, s).

    The launch files run against stand-ins that record what they are given (launch_ros is
    not always importable: the test below then skips), so the wiring is checked everywhere.
    """
    from imu_allan.nodes import allan
    for name, classes in STAND_INS.items():
        module = ModuleType(name)
        for cls in classes:
            setattr(module, cls, type(cls, (Recorded,), {}))
        monkeypatch.setitem(sys.modules, name, module)
    param = next(p for p in allan.PARAMETERS if p.name == 'filter_window_s')
    assert (param.default, param.range, param.read_only) == (0.0, (0.0, 1.0), True)
    for arguments, taps in (({}, 15), ({'filter_window': '7'}, 7)):
        nodes = expand('gx3_25.launch.py', {'port': '/dev/ttyX', **arguments})
        assert sorted(nodes) == ['allan', 'denoise', 'driver']
        assert given(nodes['driver'], 'filter_window') == taps
        assert given(nodes['allan'], 'filter_window_s') == pytest.approx(taps / 1000.0)
        assert given(nodes['denoise'], 'filter_window_s') is None
        assert given(nodes['allan'], 'rate_hz') == given(nodes['driver'], 'rate_hz') == 100.0
    # monitor.launch.py alone leaves it to the parameter files (packaged: 0, unknown)
    assert given(expand('monitor.launch.py', {})['allan'], 'filter_window_s') is None
    assert given(expand('monitor.launch.py', {'filter_window_s': '0.02'})['allan'],
                 'filter_window_s') == 0.02


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
        # The factory window (15 taps at decimation 10) correlates consecutive samples: the
        # driver and allan get it from the launch argument, and the fit gives white noise
        # the shape it makes.
        launch = Launch(tmp_path, domain, 'gx3_25.launch.py', f'port:={port}',
                        'rate_hz:=100.0', f'params_file:={params}')
        try:
            assert spin_until(executor, lambda: coeffs, 120), launch.log.read_text()
            window = get_parameters(node, executor, '/allan', ['filter_window_s'])
            taps = get_parameters(node, executor, '/driver', ['filter_window'])
        finally:
            status, out = launch.stop()  # the driver goes before the simulator
    finally:
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)
    assert window[0].double_value == pytest.approx(0.015) and taps[0].integer_value == 15
    table = decode_coeffs(coeffs[-1])
    assert np.isfinite(table[:, 1, 0]).sum() >= 3, table[:, 1]  # white noise, several axes
    check_clean_shutdown(status, out, ['driver', 'allan', 'denoise'])


def get_parameters(node, executor, target, names):
    """Return a node's parameters as ParameterValue messages (its get_parameters service)."""
    from rcl_interfaces.srv import GetParameters
    client = node.create_client(GetParameters, f'{target}/get_parameters')
    try:
        assert client.wait_for_service(timeout_sec=30), target
        future = client.call_async(GetParameters.Request(names=names))
        assert spin_until(executor, future.done, 30), target
        return future.result().values
    finally:
        node.destroy_client(client)


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
