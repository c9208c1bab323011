"""
The ``sensor_msgs/Temperature`` topic of a bag (rosbag2 sqlite3/MCAP, ROS 1), read with rosbags.

A temperature topic is small (the driver publishes 1 message/s), so the generic rosbags
deserializer is fast enough here; the Imu topic keeps its bulk readers
(:mod:`imu_allan.formats.bag_reader`), untouched by this module.
"""

import math

import numpy as np

from .bag_reader import any_reader, bag_kind
from .samples import Temperatures
from ..errors import InputError

#: Message type names of sensor_msgs/Temperature (ROS 2 and ROS 1 spelling).
TEMPERATURE_TYPES = {'sensor_msgs/msg/Temperature', 'sensor_msgs/Temperature'}


def choose_temperature_topic(topics, imu_topic=''):
    """
    Return the Temperature topic to read among ``topics`` (names), or None.

    Several: the one in the Imu topic's namespace (``/imu/temperature`` beside
    ``/imu/data_raw``), else the first in name order.
    """
    if not topics:
        return None
    topics = sorted(topics)
    space = imu_topic.rsplit('/', 1)[0] + '/' if '/' in imu_topic.strip('/') else None
    if space:
        near = [t for t in topics if t.startswith(space)]
        if near:
            return near[0]
    return topics[0]


def read_temperature(path, imu_topic='', topic=None, topic_types=None):
    """
    Read the temperatures of a bag.

    Returns :class:`~.samples.Temperatures` ``(topic, t, celsius)`` (header stamps in s on
    the clock of the Imu stamps, deg C, sorted by time, non-finite values and invalid stamps
    left out) or None when the bag has
    no ``sensor_msgs/Temperature`` topic (or only an empty one).  A bag rosbags cannot open
    also gives None: the Imu readers report the damage, the temperature is only extra.
    ``topic`` picks one; ``imu_topic`` guides the default choice
    (:func:`choose_temperature_topic`).  ``topic_types``: ``{topic: type}`` of the bag when
    the Imu reader listed them (``Samples.topic_types``); without a Temperature type among
    them the bag is not opened again (rosbags counts every row of a sqlite3 bag on opening).
    """
    if topic_types is not None and not TEMPERATURE_TYPES & set(topic_types.values()):
        return None
    _, p = bag_kind(path)
    try:
        reader = any_reader([p], str(path))
    except InputError:
        return None
    try:
        found = {c.topic for c in reader.connections if c.msgtype in TEMPERATURE_TYPES}
        chosen = topic if topic in found else choose_temperature_topic(found, imu_topic)
        if chosen is None:
            return None
        conns = [c for c in reader.connections if c.topic == chosen]
        stamps, values = [], []
        try:
            for conn, _, raw in reader.messages(connections=conns):
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception:  # a garbled message: skip it, as the Imu readers do
                    continue
                stamp = msg.header.stamp
                if stamp.nanosec >= 1_000_000_000 or not math.isfinite(msg.temperature):
                    continue
                stamps.append(stamp.sec + stamp.nanosec * 1e-9)
                values.append(float(msg.temperature))
        except Exception:  # a damaged chunk ends the topic: keep what was read
            pass
    finally:
        reader.close()
    if not stamps:
        return None
    t = np.asarray(stamps, dtype=np.float64)
    order = np.argsort(t, kind='stable')
    return Temperatures(chosen, t[order], np.asarray(values, dtype=np.float64)[order])
