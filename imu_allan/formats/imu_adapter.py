"""
The one adapter from a ``sensor_msgs/msg/Imu`` message to numpy.

Live nodes (rclpy messages) and the offline tool (rosbags message objects) both call these
functions, so both see exactly the same numbers for the same message. Only attribute access is
used (``header.stamp.sec``, ``angular_velocity.x``, ...): rclpy and rosbags objects share the
field names, and no ROS import is needed here.
"""

import numpy as np

from ..core.units import AXES


def stamp_seconds(stamp):
    """
    Return a ``builtin_interfaces/Time`` (``sec``, ``nanosec``) as float seconds.

    ROS 1 messages deserialized by rosbags use the same ``sec``/``nanosec`` names.
    """
    return stamp.sec + stamp.nanosec * 1e-9


def imu_to_row(msg):
    """
    Convert one Imu message (rclpy or rosbags) to ``(stamp_s, row)``.

    ``stamp_s``: header stamp in s (``sec + nanosec * 1e-9``); ``row`` (6,): angular velocity
    in rad/s, then linear acceleration in m/s^2 (:data:`imu_allan.core.units.AXES` order).
    """
    w = msg.angular_velocity
    a = msg.linear_acceleration
    row = np.array([w.x, w.y, w.z, a.x, a.y, a.z], dtype=np.float64)
    return stamp_seconds(msg.header.stamp), row


def imus_to_arrays(msgs):
    """Convert Imu messages to ``(t, data)``: (n,) stamps in s, (n, 6) as :func:`imu_to_row`."""
    msgs = list(msgs)
    n = len(msgs)
    t = np.empty(n, dtype=np.float64)
    data = np.empty((n, len(AXES)), dtype=np.float64)
    for i, msg in enumerate(msgs):
        w = msg.angular_velocity
        a = msg.linear_acceleration
        t[i] = stamp_seconds(msg.header.stamp)
        data[i] = (w.x, w.y, w.z, a.x, a.y, a.z)
    return t, data
