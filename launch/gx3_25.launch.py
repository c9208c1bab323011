"""
A LORD MicroStrain 3DM-GX3-25 on a serial port: the driver plus the monitor.

    ros2 launch imu_allan gx3_25.launch.py port:=/dev/ttyACM0

Starts ``driver`` (publishing ``imu/data_raw``) with the packaged ``config/driver.yaml``, and
``allan`` + ``denoise`` on ``imu/data_raw`` as ``monitor.launch.py`` does.  Arguments:

* ``port``, ``baud``: the serial link (a ``/dev/serial/by-id/...`` path survives
  re-enumeration);
* ``rate_hz``: the device's output rate, Hz; given to the driver and, as the configured rate,
  to allan and denoise (the device's own timer stamps the samples);
* ``filter_window``: the device's gyro/accel moving-average window, samples of its 1 kHz
  internal stream (1..32, factory 15); given to the driver, which sets it with 0xDB, and to
  allan as ``filter_window_s`` = filter_window / 1000 s (the processing its data went through);
* ``params_file``: a parameter file for all three nodes, applied after the packaged ones
  (sections ``driver:``, ``allan:``, ``denoise:`` or ``/**:``); ``rate_hz`` and
  ``filter_window`` are given after it, so the launch arguments win.
"""

import os

from ament_index_python.packages import get_package_share_directory
from imu_allan.device.gx3_protocol import BASE_RATE_HZ
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch_ros.actions import Node

ARGUMENTS = (
    ('port', '/dev/ttyACM0', 'serial port of the 3DM-GX3-25'),
    ('baud', '115200', 'baud rate: 115200, 230400, 460800 or 921600'),
    ('rate_hz', '100.0', 'output rate, Hz (1000 / decimation)'),
    ('filter_window', '15', 'gyro/accel moving-average window, samples at 1 kHz (1..32)'),
    ('params_file', '', 'extra parameter file for driver, allan and denoise (empty: none)'),
)


def gx3_nodes(context):
    """Return the driver and the monitor for the arguments, one window for both."""
    arg = context.launch_configurations
    share = get_package_share_directory('imu_allan')
    params = [os.path.join(share, 'config', 'driver.yaml')]
    if arg['params_file'].strip():
        params.append(arg['params_file'])
    window = int(arg['filter_window'])
    driver = Node(package='imu_allan', executable='driver', name='driver', output='screen',
                  parameters=params + [{'port': arg['port'], 'baud': int(arg['baud']),
                                        'rate_hz': float(arg['rate_hz']),
                                        'filter_window': window}])
    monitor = IncludeLaunchDescription(
        PythonLaunchDescriptionSource(os.path.join(share, 'launch', 'monitor.launch.py')),
        launch_arguments=[('imu_topic', 'imu/data_raw'), ('rate_hz', arg['rate_hz']),
                          ('filter_window_s', str(window / BASE_RATE_HZ)),
                          ('params_file', arg['params_file'])])
    return [driver, monitor]


def generate_launch_description():
    """Declare the arguments; build the nodes once they are known."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, default, text in ARGUMENTS]
        + [OpaqueFunction(function=gx3_nodes)])
