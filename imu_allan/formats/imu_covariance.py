"""
The covariance an Imu topic's messages state: what the publisher says one sample's noise is.

``sensor_msgs/Imu`` carries ``angular_velocity_covariance`` and ``linear_acceleration_covariance``
(row-major 3x3, SI: rad^2/s^2 and m^2/s^4); all zeros means "unknown" and element 0 = -1
"not provided" (the message's own comments).  A simulator fills them from its configuration, so
they do not change from message to message: a bounded sample is read with the ``rosbags``
deserializer (the first few messages and a few spread over the bag through its time index),
not the whole topic (the bulk Imu readers, :mod:`imu_allan.formats.bag_reader`, skip these
fields).  Messages that disagree with each other are reported, not averaged.
"""

import numpy as np

from .bag_reader import any_reader, bag_kind
from ..core.units import AXES
from ..errors import InputError

#: Messages read at the start of the topic and at evenly spread times after it.
FIRST = 3
SPREAD = 5


def _diagonals(msg):
    """Angular-velocity and linear-acceleration diagonals of one message (6 values, SI)."""
    w = np.asarray(msg.angular_velocity_covariance, dtype=float).reshape(9)
    a = np.asarray(msg.linear_acceleration_covariance, dtype=float).reshape(9)
    return np.concatenate([w[[0, 4, 8]], a[[0, 4, 8]]]), w[0] == -1.0, a[0] == -1.0


def _sample(reader, conns):
    """Deserialized messages: the first :data:`FIRST`, then one at each of SPREAD times."""
    msgs = []
    for i, (conn, _, raw) in enumerate(reader.messages(connections=conns)):
        msgs.append(reader.deserialize(raw, conn.msgtype))
        if i + 1 >= FIRST:
            break
    start, end = reader.start_time, reader.end_time
    for k in range(1, SPREAD + 1):
        at = start + (end - start) * k // (SPREAD + 1)
        for conn, _, raw in reader.messages(connections=conns, start=at):
            msgs.append(reader.deserialize(raw, conn.msgtype))
            break
    return msgs


def read_covariance(path, topic):
    """
    Return the stated per-sample variance of each axis of an Imu topic, and notes.

    ``({axis: variance (SI)}, notes)``: axes whose covariance is unknown (all zeros), not
    provided (-1) or not the same in every message read are left out, each with a note.
    A bag that rosbags cannot open, or a topic that cannot be decoded, gives ``({},
    [note])``: the samples were read by the bulk readers already, the covariance is extra.
    """
    where = str(path)
    try:
        _, p = bag_kind(path)
        reader = any_reader([p], where)
    except InputError as exc:
        return {}, [f'{where}: message covariance not read ({exc.problem})']
    try:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            return {}, [f'{where}: no topic {topic}: message covariance not read']
        try:
            msgs = _sample(reader, conns)
        except Exception as exc:  # noqa: BLE001 - a damaged bag: the covariance is extra
            return {}, [f'{where}:{topic}: message covariance not read '
                        f'({" ".join(str(exc).split())[:120]})']
    finally:
        reader.close()
    if not msgs:
        return {}, []
    rows, gyro_absent, accel_absent = zip(*(_diagonals(m) for m in msgs))
    rows = np.array(rows)
    out, notes, unknown, varying = {}, [], [], []
    for j, axis in enumerate(AXES):
        if (gyro_absent if j < 3 else accel_absent)[0]:
            continue
        values = rows[:, j]
        if not np.all(np.isfinite(values)) or np.all(values == 0):
            unknown.append(axis)
        elif np.ptp(values) > 1e-9 * np.max(np.abs(values)):
            varying.append(axis)
        elif values[0] > 0:
            out[axis] = float(values[0])
    if unknown:
        notes.append(f'{where}:{topic}: covariance of {", ".join(unknown)} is zero (unknown): '
                     f'not compared')
    if varying:
        notes.append(f'{where}:{topic}: covariance of {", ".join(varying)} changes between '
                     f'messages: not compared')
    if any(g for g in gyro_absent) or any(a for a in accel_absent):
        notes.append(f'{where}:{topic}: a covariance marked not provided (-1)')
    return out, notes
