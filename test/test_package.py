"""The package is a real ament_python package and every executable is where ros2 run looks."""

import os
from pathlib import Path

from conftest import executable, EXECUTABLES, REPO, run_command
import pytest

pytestmark = pytest.mark.ros


def test_package_xml_is_a_valid_ros_manifest():
    # An invalid maintainer email makes colcon silently build a plain Python package without
    # the ament hook, so ros2 run would not find it: parse it the way colcon does.
    from catkin_pkg.package import parse_package
    pkg = parse_package(str(REPO / 'package.xml'))
    assert pkg.name == 'imu_allan'
    assert pkg.package_format == 3
    assert pkg.get_build_type() == 'ament_python'
    names = {d.name for d in pkg.exec_depends}
    for dep in ('rclpy', 'sensor_msgs', 'std_msgs', 'diagnostic_msgs', 'python3-numpy',
                'python3-scipy', 'python3-serial', 'python3-pywt', 'python3-rosbags-pip'):
        assert dep in names
    pkg.validate()


def test_ament_index_marker_found_like_ros2_run():
    from ament_index_python.packages import get_package_prefix, get_package_share_directory
    prefix = get_package_prefix('imu_allan')
    marker = Path(prefix) / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'imu_allan'
    assert marker.is_file()
    share = Path(get_package_share_directory('imu_allan'))
    assert (share / 'package.xml').is_file()
    assert sorted(p.name for p in (share / 'config').glob('*.yaml')) >= ['allan.yaml',
                                                                         'denoise.yaml',
                                                                         'driver.yaml']


def test_executables_are_in_lib_and_only_once():
    from ament_index_python.packages import get_package_prefix
    lib = Path(get_package_prefix('imu_allan')) / 'lib' / 'imu_allan'
    found = sorted(p.name for p in lib.iterdir() if os.access(p, os.X_OK) and p.is_file())
    assert found == sorted(EXECUTABLES)


@pytest.mark.parametrize('name', EXECUTABLES)
def test_every_executable_answers_help(name):
    proc = run_command(name, '--help', timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert 'usage' in proc.stdout.lower()
    assert 'Traceback' not in proc.stderr
    assert executable(name).endswith(os.path.join('lib', 'imu_allan', name))
