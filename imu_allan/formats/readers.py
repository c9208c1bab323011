"""
One entry point for every input format: ``read_samples(path, fmt='auto', topic=None)``.

Formats: ``rosbag2`` (folder with ``metadata.yaml``, bare ``.db3`` or ``.mcap``), ``ros1``
(``.bag``), ``csv`` (contract CSV), ``thesis`` (thesis text log), ``gx3raw`` (raw 3DM-GX3-25
serial capture). ``auto`` looks at the path (folder, extension) and then at the content (file
signatures, the first text lines, the GX3 command bytes 0xCB/0xC2/0xCF).
"""

from pathlib import Path

from . import FORMATS
from .bag_reader import bag_kind, MCAP_MAGIC, read_bag, ROS1_MAGIC, SQLITE_MAGIC
from .csv_samples import read_csv
from .input_file import regular_input
from .thesis_log import looks_like_thesis_log, read_thesis_log
from ..errors import InputError

_GX3_CODES = (0xCB, 0xC2, 0xCF)


def detect_format(path):
    """Return the format name of an input, or raise InputError saying why it is unknown."""
    p = Path(path)
    if not p.exists():
        raise InputError(path, 'no such file or directory')
    if p.is_dir():
        return 'rosbag2'
    suffix = p.suffix.lower()
    if suffix in ('.db3', '.mcap'):
        return 'rosbag2'
    if suffix == '.bag':
        return 'ros1'
    if suffix == '.csv':
        return 'csv'
    try:
        with open(p, 'rb') as f:
            head = f.read(4096)
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    if not head:
        raise InputError(path, 'empty file')
    if head.startswith(MCAP_MAGIC) or head.startswith(SQLITE_MAGIC):
        return 'rosbag2'
    if head.startswith(ROS1_MAGIC):
        return 'ros1'
    if head[0] in _GX3_CODES:
        return 'gx3raw'
    try:
        text = head.decode('utf-8')
    except UnicodeDecodeError:
        text = None
    if text is not None:
        first = next((ln.strip() for ln in text.splitlines()
                      if ln.strip() and not ln.startswith('#')), '')
        names = [c.strip() for c in first.split(',')]
        if 't' in names or any(n.startswith(('gyro_', 'accel_')) for n in names):
            return 'csv'
        if looks_like_thesis_log(text):
            return 'thesis'
    raise InputError(path, 'unknown input format (use --format '
                           'rosbag2|ros1|csv|thesis|gx3raw)')


def read_samples(path, fmt='auto', topic=None, fast=True, temperature=False):
    """
    Read IMU samples (t in s, data in SI, axes in AXES order) from a file or rosbag2 folder.

    ``fmt``: one of :data:`FORMATS`.  Bags only: ``topic`` the Imu topic, ``fast`` the bulk
    decoder (False: the generic deserializer, same numbers), ``temperature`` also a
    ``sensor_msgs/Temperature`` topic into ``Samples.temperature``
    (:func:`~.temperature_bag.read_temperature`; None when there is none).  Raises
    :class:`InputError` for an unknown format or any problem the chosen reader reports.
    """
    if fmt not in FORMATS:
        raise InputError('--format', f'unknown format {fmt!r} (one of {", ".join(FORMATS)})')
    real = regular_input(path)  # a FIFO is copied once a writer appears; devices are refused
    if real == Path(path):
        return _read(path, fmt, topic, fast, temperature)
    try:
        samples = _read(real, fmt, topic, fast, temperature)
    except InputError as err:  # name the user's path, not the temporary copy
        raise InputError(path, err.problem.replace(str(real), str(path))) from None
    samples.source = samples.source.replace(str(real), str(path))
    return samples


def _read(path, fmt, topic, fast, temperature=False):
    if fmt == 'auto':
        fmt = detect_format(path)
    elif not Path(path).exists():
        raise InputError(path, 'no such file or directory')
    if fmt in ('rosbag2', 'ros1'):
        kind = bag_kind(path)[0]
        if fmt == 'ros1' and kind != 'ros1':
            raise InputError(path, 'not a ROS 1 bag')
        if fmt == 'rosbag2' and kind == 'ros1':
            raise InputError(path, 'a ROS 1 bag, not rosbag2 (use --format ros1)')
        samples = read_bag(path, topic=topic, fast=fast)
        if temperature:
            samples.temperature = _temperature(path, samples)
        return samples
    if fmt == 'csv':
        return read_csv(path)
    if fmt == 'thesis':
        return read_thesis_log(path)
    # Imported here: the raw-capture reader belongs to the driver's protocol layer.
    from .gx3raw import read_gx3raw
    return read_gx3raw(path)


def _temperature(path, samples):
    """Return the bag's Temperature readings beside ``samples``; None: none, or unreadable."""
    from .temperature_bag import read_temperature
    try:
        return read_temperature(path, imu_topic=samples.topic or '',
                                topic_types=samples.topic_types)
    except InputError:  # the temperature is only extra: the Imu readers report damage
        return None
