"""
Monitor an existing IMU: the allan and denoise nodes on any ``sensor_msgs/Imu`` topic.

    ros2 launch imu_allan monitor.launch.py imu_topic:=/my_imu/data

Launch arguments:

* ``imu_topic``: the Imu topic to monitor (remapped onto the nodes' ``imu/data_raw``);
* ``rate_hz``: its sample rate, Hz; empty (the default) keeps the parameter files' value, which
  is 0 in the packaged ones: measured from the header stamps;
* ``filter_window_s``: the moving average the IMU applies before it outputs, s, for allan;
  empty (the default) keeps the parameter files' value (packaged: 0 = unknown);
* ``params_file``: a parameter file for both nodes, applied after the packaged
  ``config/allan.yaml`` and ``config/denoise.yaml`` (sections ``/**/allan:``, ``/**/denoise:`` or
  ``/**:``);
* ``namespace``: the namespace of both nodes and of their output topics.

"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

ARGUMENTS = (
    ('imu_topic', 'imu/data_raw', 'sensor_msgs/Imu topic to monitor'),
    ('rate_hz', '', 'sample rate of imu_topic, Hz (empty: from the parameter files; the '
                    'packaged ones say 0 = measured from the stamps)'),
    ('filter_window_s', '', 'moving average the IMU applies, s, for allan (empty: from the '
                            'parameter files; the packaged one says 0 = unknown)'),
    ('params_file', '', 'extra parameter file for allan and denoise (empty: none)'),
    ('namespace', '', 'namespace of the nodes and their topics'),
)


def monitor_nodes(context):
    """Return the allan and denoise nodes for the current launch arguments."""
    arg = context.launch_configurations
    share = get_package_share_directory('imu_allan')
    overrides = {}
    if arg['rate_hz'].strip():
        overrides['rate_hz'] = float(arg['rate_hz'])
    nodes = []
    for name in ('allan', 'denoise'):
        params = [os.path.join(share, 'config', f'{name}.yaml')]
        if arg['params_file'].strip():
            params.append(arg['params_file'])
        extra = dict(overrides)
        if name == 'allan' and arg['filter_window_s'].strip():
            extra['filter_window_s'] = float(arg['filter_window_s'])
        nodes.append(Node(package='imu_allan', executable=name, name=name,
                          namespace=arg['namespace'], output='screen',
                          parameters=params + [extra],
                          remappings=[('imu/data_raw', arg['imu_topic'])]))
    return nodes


def generate_launch_description():
    """Declare the arguments; build the nodes once they are known."""
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, default, text in ARGUMENTS]
        + [OpaqueFunction(function=monitor_nodes)])
