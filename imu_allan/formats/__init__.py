"""
Samples in and out: the Imu CDR codec, rosbag2 (sqlite3, MCAP), ROS 1, CSV, logs, captures.

Nothing is imported here, so that commands can list :data:`FORMATS` without loading a reader.
"""

#: Input formats ``read_samples`` and the commands' ``--format`` accept.
FORMATS = ('auto', 'rosbag2', 'ros1', 'csv', 'thesis', 'gx3raw')
