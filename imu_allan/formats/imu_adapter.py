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
    Convert one Imu message to ``(stamp_s, row)``.

    Parameters
    ----------
    msg : sensor_msgs/msg/Imu
        An rclpy or rosbags message object.

    Returns
    -------
    stamp_s : float
        Header stamp in seconds (``sec + nanosec * 1e-9``).
    row : numpy.ndarray
        Shape (6,), ``[gx, gy, gz, ax, ay, az]``: angular velocity in rad/s, then linear
        acceleration in m/s^2 (the package axis order :data:`imu_allan.core.units.AXES`).

    """
    w = msg.angular_velocity
    a = msg.linear_acceleration
    row = np.array([w.x, w.y, w.z, a.x, a.y, a.z], dtype=np.float64)
    return stamp_seconds(msg.header.stamp), row


def imus_to_arrays(msgs):
    """
    Convert a sequence of Imu messages to ``(t, data)``.

    Returns
    -------
    t : numpy.ndarray
        Shape (n,), header stamps in seconds.
    data : numpy.ndarray
        Shape (n, 6), rad/s then m/s^2, columns in :data:`imu_allan.core.units.AXES` order.

    """
    msgs = list(msgs)
    n = len(msgs)
    t = np.empty(n, dtype=np.float64)
    data = np.empty((n, len(AXES)), dtype=np.float64)
    for i, msg in enumerate(msgs):
        w = msg.angular_velocity
        a = msg.linear_acceleration
        st = msg.header.stamp
        t[i] = st.sec + st.nanosec * 1e-9
        data[i] = (w.x, w.y, w.z, a.x, a.y, a.z)
    return t, data


def cdr_to_arrays(blobs):
    """
    Convert serialized (CDR) Imu messages to ``(t, data)`` like :func:`imus_to_arrays`.

    The live nodes take raw bytes from their subscription and decode them here in bulk with
    the bag reader's fixed-layout decoder (:func:`imu_allan.formats.imu_cdr.decode_rows`), about
    ten times cheaper than building a Python message per sample; anything the layout does not
    cover (big-endian CDR, odd lengths) is deserialized one by one and goes through
    :func:`imu_to_row`, so the numbers are the same either way.
    """
    from .imu_cdr import decode_rows, deserialize  # imu_layout imports this module
    n = len(blobs)
    t = np.empty(n, dtype=np.float64)
    data = np.empty((n, len(AXES)), dtype=np.float64)
    lengths = np.fromiter((len(b) for b in blobs), dtype=np.int64, count=n)
    for length in np.unique(lengths):
        idx = np.flatnonzero(lengths == length)
        rows = np.frombuffer(b''.join(blobs[i] for i in idx), dtype=np.uint8)
        ok, t_rows, d_rows = decode_rows(rows.reshape(idx.size, int(length)), ros1=False)
        t[idx[ok]], data[idx[ok]] = t_rows[ok], d_rows[ok]
        for i in idx[~ok]:
            t[i], data[i] = imu_to_row(deserialize(bytes(blobs[i])))
    return t, data
