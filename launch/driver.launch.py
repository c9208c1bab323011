"""Launch the 3DM-GX3-25 driver with config/driver.yaml (port overridable: port:=...)."""

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description():
    """Driver node with the packaged parameters; ``port`` and ``rate_hz`` as arguments."""
    params = os.path.join(get_package_share_directory('imu_allan'), 'config', 'driver.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('port', default_value='/dev/ttyACM0'),
        DeclareLaunchArgument('rate_hz', default_value='100.0'),
        Node(package='imu_allan', executable='driver', name='driver', output='screen',
             parameters=[params, {'port': LaunchConfiguration('port'),
                                  'rate_hz': LaunchConfiguration('rate_hz')}]),
    ])
