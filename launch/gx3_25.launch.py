"""
A LORD MicroStrain 3DM-GX3-25 on a serial port: the driver plus the monitor.

    ros2 launch imu_allan gx3_25.launch.py port:=/dev/ttyACM0

Starts ``driver`` (publishing ``imu/data_raw``) with the packaged ``config/driver.yaml``, and
``allan`` + ``denoise`` on ``imu/data_raw`` as ``monitor.launch.py`` does.  Arguments:

* ``port``, ``baud``: the serial link (a ``/dev/serial/by-id/...`` path survives
  re-enumeration);
* ``rate_hz``: the device's output rate, Hz; given to the driver and, as the configured rate,
  to allan and denoise (the device's own timer stamps the samples);
* ``params_file``: a parameter file for all three nodes, applied after the packaged ones
  (sections ``driver:``, ``allan:``, ``denoise:`` or ``/**:``).
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGUMENTS = (
    ('port', '/dev/ttyACM0', 'serial port of the 3DM-GX3-25'),
    ('baud', '115200', 'baud rate: 115200, 230400, 460800 or 921600'),
    ('rate_hz', '100.0', 'output rate, Hz (1000 / decimation)'),
    ('params_file', '', 'extra parameter file for driver, allan and denoise (empty: none)'),
)


def driver_node(context):
    """Return the driver with the packaged parameters, ``params_file`` and the arguments."""
    arg = context.launch_configurations
    params = [os.path.join(get_package_share_directory('imu_allan'), 'config', 'driver.yaml')]
    if arg['params_file'].strip():
        params.append(arg['params_file'])
    return [Node(package='imu_allan', executable='driver', name='driver', output='screen',
                 parameters=params + [{'port': arg['port'], 'baud': int(arg['baud']),
                                       'rate_hz': float(arg['rate_hz'])}])]


def generate_launch_description():
    """Declare the arguments; build the nodes once they are known."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, default, text in ARGUMENTS]
        + [OpaqueFunction(function=driver_node),
           IncludeLaunchDescription(
               PythonLaunchDescriptionSource(os.path.join(
                   get_package_share_directory('imu_allan'), 'launch', 'monitor.launch.py')),
               launch_arguments=[('imu_topic', 'imu/data_raw'),
                                 ('rate_hz', LaunchConfiguration('rate_hz')),
                                 ('params_file', LaunchConfiguration('params_file'))])])
