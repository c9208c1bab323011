"""
Write ``sensor_msgs/msg/Imu`` samples as real bags (rosbag2 MCAP/sqlite3, ROS 1) with rosbags.

Messages are serialized in bulk with numpy into the fixed layout of ``sensor_msgs/Imu`` (see
:mod:`imu_allan.formats.bag_reader`); the bytes equal what ``rosbags``' ``serialize_cdr`` /
``serialize_ros1`` give for the same message (checked in the tests). Each message carries the
sample time as header stamp and as receive time, ``orientation_covariance[0] = -1`` (no
orientation, as on ``imu/data_raw``), zero covariances otherwise. Axes missing from the samples
are written as 0.
"""

from binascii import crc32
import mmap
from pathlib import Path
import struct

import numpy as np

from .imu_cdr import encode_imu, IMU_TYPE
from ..core.units import AXES
from ..errors import InputError

STORAGES = ('mcap', 'sqlite3', 'ros1')


def _six_columns(samples):
    """Return the samples as (n, 6) in AXES order, absent axes as 0."""
    data = np.asarray(samples.data, dtype=np.float64)
    full = np.zeros((data.shape[0], 6))
    for j, axis in enumerate(samples.axes):
        full[:, AXES.index(axis)] = data[:, j]
    return full


def _check_new(path):
    p = Path(path)
    if p.exists():
        raise InputError(path, 'output already exists')
    if not p.parent.exists():
        raise InputError(path, 'parent folder does not exist')
    return p


def write_imu_bag(path, samples, topic='/imu/data_raw', storage='mcap', frame_id='imu_link',
                  extra_topics=None, compress=False):
    """
    Write samples (t in s, data in SI) as an Imu bag on ``topic``; return its path.

    ``path`` must not exist: a rosbag2 folder (``storage`` ``'mcap'``, Jazzy's default, or
    ``'sqlite3'``; metadata version 9, as Jazzy) or a ROS 1 ``.bag`` file (``'ros1'``).
    ``extra_topics``: ``{topic: Samples}`` (written as Imu like the main topic) or ``{topic:
    (msgtype, [(stamp_ns, message object), ...])}`` with messages built with the matching
    rosbags typestore (ROS2_JAZZY, or ROS1_NOETIC for ``ros1``); an empty list makes a topic
    without messages.  ``compress``: zstd chunk compression (MCAP only).
    """
    from rosbags.typesys import get_typestore, Stores
    if storage not in STORAGES:
        raise InputError('storage', f'unknown storage {storage!r} (one of {", ".join(STORAGES)})')
    p = _check_new(path)
    ros1 = storage == 'ros1'
    rows, stamp_ns = encode_imu(samples.t, _six_columns(samples), frame_id, ros1=ros1)
    extra_topics = extra_topics or {}
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1
        ts = get_typestore(Stores.ROS1_NOETIC)
        writer = Writer1(p)
        serialize = ts.serialize_ros1
    else:
        from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
        ts = _jazzy()
        plugin = StoragePlugin.MCAP if storage == 'mcap' else StoragePlugin.SQLITE3
        writer = Writer(p, version=9, storage_plugin=plugin)
        if compress and storage == 'mcap':
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        serialize = ts.serialize_cdr
    with writer:
        streams = [(writer.add_connection(topic, IMU_TYPE, typestore=ts), stamp_ns, rows)]
        for name, value in extra_topics.items():
            if hasattr(value, 't') and hasattr(value, 'data'):
                c = writer.add_connection(name, IMU_TYPE, typestore=ts)
                r, st = encode_imu(value.t, _six_columns(value), frame_id, ros1=ros1)
                streams.append((c, st, r))
                continue
            msgtype, msgs = value
            c = writer.add_connection(name, msgtype, typestore=ts)
            st = np.array([int(x) for x, _ in msgs], dtype=np.int64)
            streams.append((c, st, [serialize(m, msgtype) for _, m in msgs]))
        _write_merged(writer, streams)
    if storage == 'mcap':
        fix_mcap_chunk_crcs(p)
    return p


def fix_mcap_chunk_crcs(folder):
    """
    Store each chunk's CRC-32 in the MCAP files of a rosbag2 folder written by rosbags.

    rosbags 0.11 writes ``uncompressed_crc`` 0 ("not computed", MCAP specification, Chunk
    record), so a flipped byte in a chunk would go unnoticed by every reader; this fills in the
    CRC-32 of each chunk's uncompressed records, which readers (ours, rosbags, the mcap
    libraries) then verify.
    """
    from .mcap_scan import decompress_chunk
    for path in Path(folder).glob('*.mcap'):
        with open(path, 'r+b') as stream:
            mm = mmap.mmap(stream.fileno(), 0)
            try:
                pos = 8  # after the magic
                while pos + 9 <= len(mm):
                    op = mm[pos]
                    (length,) = struct.unpack_from('<Q', mm, pos + 1)
                    if op == 0x06:  # Chunk: start, end, size u64, crc u32, compression, records
                        (usize,) = struct.unpack_from('<Q', mm, pos + 25)
                        (n,) = struct.unpack_from('<I', mm, pos + 37)
                        comp = mm[pos + 41:pos + 41 + n].decode()
                        (csize,) = struct.unpack_from('<Q', mm, pos + 41 + n)
                        start = pos + 49 + n
                        records = decompress_chunk(comp, mm[start:start + csize], usize)
                        struct.pack_into('<I', mm, pos + 33, crc32(records))
                    elif op in (0x0F, 0x02):  # DataEnd or Footer: no chunk after this
                        break
                    pos += 9 + length
                mm.flush()
            finally:
                mm.close()


def _write_merged(writer, streams):
    """Write (connection, stamps_ns, rows) streams in receive-time order (ties: stream order)."""
    stamps = np.concatenate([st for _, st, _ in streams])
    which = np.concatenate([np.full(st.shape[0], k) for k, (_, st, _) in enumerate(streams)])
    index = np.concatenate([np.arange(st.shape[0]) for _, st, _ in streams])
    order = np.lexsort((which, stamps))
    write = writer.write
    for s, k, i in zip(stamps[order].tolist(), which[order].tolist(), index[order].tolist()):
        conn, _, rows = streams[k]
        row = rows[i]
        write(conn, s, row if isinstance(row, bytes) else row.tobytes())


def copy_bag_with_topic(src, dst, topic, samples, frame_id='imu_link', compress=False):
    """
    Copy every connection and message of bag ``src`` into a new MCAP rosbag2 ``dst``, plus a topic.

    Used by ``analyze --denoise`` to write ``imu/data_denoised`` next to the original topics:
    ``samples`` (s, SI) become the new Imu ``topic`` (which must not exist in ``src``), its
    receive times their header stamps.  ROS 1 sources are converted to CDR; messages are
    written in receive-time order; ``compress``: zstd chunk compression.
    """
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    from .bag_reader import any_reader, bag_kind

    bag_kind(src)  # raises InputError for a missing path or a non-bag
    p = _check_new(dst)
    rows, stamp_ns = encode_imu(samples.t, _six_columns(samples), frame_id)
    reader = any_reader([bag_kind(src)[1]], str(src))
    try:
        if any(c.topic == topic for c in reader.connections):
            raise InputError(src, f'topic {topic} already exists in the bag')
        writer = Writer(p, version=9, storage_plugin=StoragePlugin.MCAP)
        if compress:
            writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        try:
            with writer:
                out, converters = {}, {}
                dst_store = reader.typestore if reader.is2 else _ros2_store_for(reader.typestore)
                for c in reader.connections:
                    key = (c.topic, c.msgtype)
                    if key not in out:
                        qos = getattr(c.ext, 'offered_qos_profiles', ())
                        out[key] = writer.add_connection(
                            c.topic, c.msgtype, typestore=dst_store,
                            offered_qos_profiles=qos)
                        converters[key] = None if reader.is2 else _ros1_converter(
                            reader.typestore, dst_store, c.msgtype)
                new = writer.add_connection(topic, IMU_TYPE, typestore=_jazzy())
                stamps = stamp_ns.tolist()
                i = 0
                for c, ts_ns, raw in reader.messages():
                    while i < len(stamps) and stamps[i] < ts_ns:
                        writer.write(new, stamps[i], rows[i].tobytes())
                        i += 1
                    conv = converters[(c.topic, c.msgtype)]
                    data = raw if conv is None else conv(raw)
                    writer.write(out[(c.topic, c.msgtype)], ts_ns, data)
                for k in range(i, len(stamps)):
                    writer.write(new, stamps[k], rows[k].tobytes())
            fix_mcap_chunk_crcs(p)
        except InputError:
            raise
        except Exception as err:
            raise InputError(src, f'cannot copy bag: {" ".join(str(err).split())}') from None
    finally:
        reader.close()
    return p


def _jazzy():
    from rosbags.typesys import get_typestore, Stores
    return get_typestore(Stores.ROS2_JAZZY)


def _ros2_store_for(ros1_store):
    """Typestore for ROS 1 types written as ROS 2: Jazzy definitions win (Header without seq)."""
    from rosbags.typesys import get_typestore, Stores
    store = get_typestore(Stores.EMPTY)
    store.register({**ros1_store.fielddefs, **_jazzy().fielddefs})
    return store


def _ros1_converter(src, dst, msgtype):
    """Return a function ROS 1 bytes -> CDR bytes for one message type."""
    from rosbags.convert.converter import is_same_wireformat, migrate_message
    if is_same_wireformat(src, dst, msgtype, msgtype):
        return lambda raw: dst.ros1_to_cdr(raw, msgtype)
    cache = {}

    def convert(raw):
        # Field-by-field migration (drops header.seq), as rosbags-convert does.
        msg = src.deserialize_ros1(raw, msgtype)
        msg = migrate_message(src, dst, msgtype, msgtype, cache, msg)
        return dst.serialize_cdr(msg, msgtype)
    return convert
