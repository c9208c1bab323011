"""The one Imu message -> numpy adapter, with rclpy and rosbags messages, and the bulk codecs."""

from imu_allan.formats.collector import Collector
from imu_allan.formats.imu_adapter import imu_to_row, imus_to_arrays
from imu_allan.formats.imu_cdr import decode_rows as _decode_rows
from imu_allan.formats.imu_cdr import deserialize, encode_imu, frame_id_of
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

IMU = 'sensor_msgs/msg/Imu'
JAZZY = get_typestore(Stores.ROS2_JAZZY)
NOETIC = get_typestore(Stores.ROS1_NOETIC)


def _rosbags_imu(sec, nanosec, w, a, frame_id='imu_link'):
    ts = JAZZY.types
    return ts[IMU](
        header=ts['std_msgs/msg/Header'](
            stamp=ts['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec),
            frame_id=frame_id),
        orientation=ts['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=np.full(9, 0.5),
        angular_velocity=ts['geometry_msgs/msg/Vector3'](x=w[0], y=w[1], z=w[2]),
        angular_velocity_covariance=np.arange(9.0),
        linear_acceleration=ts['geometry_msgs/msg/Vector3'](x=a[0], y=a[1], z=a[2]),
        linear_acceleration_covariance=np.ones(9))


def test_rosbags_message_to_row():
    """A rosbags Imu gives the stamp and the six values in AXES order."""
    msg = _rosbags_imu(12, 340_000_000, (0.1, -0.2, 0.3), (1.0, 2.0, 9.81))
    stamp, row = imu_to_row(msg)
    assert stamp == 12 + 340_000_000 * 1e-9
    assert row.tolist() == [0.1, -0.2, 0.3, 1.0, 2.0, 9.81]
    t, data = imus_to_arrays([msg, msg])
    assert t.shape == (2,) and data.shape == (2, 6)
    assert data[1].tolist() == row.tolist()


@pytest.mark.ros
def test_rclpy_message_same_numbers_as_rosbags():
    """An rclpy Imu and the same bytes decoded by rosbags and by the bulk decoder agree."""
    sensor_msgs = pytest.importorskip('sensor_msgs.msg', reason='rclpy Jazzy wheels missing')
    serialization = pytest.importorskip('rclpy.serialization')
    msg = sensor_msgs.Imu()
    msg.header.stamp.sec = 1_700_000_000
    msg.header.stamp.nanosec = 123_456_789
    msg.header.frame_id = 'gx3'
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = 1e-3, -2e-3, 0.5
    a = msg.linear_acceleration
    a.x, a.y, a.z = 0.01, -0.02, 9.80261
    stamp, row = imu_to_row(msg)
    raw = serialization.serialize_message(msg)
    stamp2, row2 = imu_to_row(JAZZY.deserialize_cdr(raw, IMU))
    assert stamp == stamp2 and row.tolist() == row2.tolist()
    ok, t, data = _decode_rows(np.frombuffer(raw, np.uint8).reshape(1, -1), ros1=False)
    assert ok[0] and t[0] == stamp and data[0].tolist() == row.tolist()


@pytest.mark.parametrize('frame_id', ['', 'a', 'imu', 'imu_link', 'imu_link_1234567'])
def test_bulk_encoder_equals_rosbags_serializer(frame_id):
    """encode_imu writes the bytes serialize_cdr / serialize_ros1 write (all paddings)."""
    t = np.array([5.25, 1.7e9 + 0.125])
    d = np.array([[1, 2, 3, 4, 5, 6], [-1e-9, 2e300, -0.0, 7, 8, 9.5]], dtype=float)
    rows, _ = encode_imu(t, d, frame_id)
    rows1, _ = encode_imu(t, d, frame_id, ros1=True)
    for i in range(2):
        msg = JAZZY.deserialize_cdr(rows[i].tobytes(), IMU)
        assert msg.header.frame_id == frame_id
        assert JAZZY.serialize_cdr(msg, IMU) == rows[i].tobytes()
        assert msg.orientation_covariance[0] == -1.0
        m1 = NOETIC.deserialize_ros1(rows1[i].tobytes(), IMU)
        assert NOETIC.serialize_ros1(m1, IMU) == rows1[i].tobytes()
        assert imu_to_row(msg)[1].tolist() == d[i].tolist()
        assert imu_to_row(m1)[1].tolist() == d[i].tolist()
    for r, ros1 in ((rows, False), (rows1, True)):
        ok, tt, dd = _decode_rows(r, ros1)
        assert ok.all() and tt.tolist() == t.tolist() and np.array_equal(dd, d)


def test_bulk_decoder_rejects_big_endian_cdr():
    """Big-endian CDR (encapsulation 00 00) is left to the generic deserializer."""
    msg = _rosbags_imu(1, 2, (0.1, 0.2, 0.3), (0.4, 0.5, 0.6))
    raw = JAZZY.serialize_cdr(msg, IMU, little_endian=False)
    ok, _, _ = _decode_rows(np.frombuffer(raw, np.uint8).reshape(1, -1), ros1=False)
    assert not ok[0]


@pytest.mark.ros
def test_cdr_to_arrays_equals_the_message_adapter_on_rclpy_bytes():
    """Bulk decoding of raw bytes (the allan node's intake) equals the per-message adapter."""
    from imu_allan.formats.imu_adapter import imus_to_arrays
    from imu_allan.formats.imu_cdr import cdr_to_arrays
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu
    rng = np.random.default_rng(12)
    msgs = []
    for i, frame in enumerate(['imu_link', 'a', 'imu', 'base_imu_frame_0', 'imu_link'] * 7):
        m = Imu()
        m.header.frame_id = frame
        m.header.stamp.sec, m.header.stamp.nanosec = 1_700_000_000 + i, 123_456_789 * (i % 3)
        (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z,
         m.linear_acceleration.x, m.linear_acceleration.y,
         m.linear_acceleration.z) = rng.normal(size=6).tolist()
        msgs.append(m)
    t_ref, d_ref = imus_to_arrays(msgs)
    t, d = cdr_to_arrays([serialize_message(m) for m in msgs])
    np.testing.assert_array_equal(t, t_ref)
    np.testing.assert_array_equal(d, d_ref)


@pytest.mark.ros
@pytest.mark.parametrize('frame', ['imu_link', '', 'base_imu_frame_0'])
def test_cdr_to_arrays_one_frame_batch_equals_the_adapter(frame):
    """
    A batch of one frame_id (the node's usual one, one structured view) equals the adapter.

    Also with a damaged nanosecond field (NaN stamp, as decode_rows gives) and with one
    big-endian message in the batch (then every message takes the general path).
    """
    from imu_allan.formats.imu_cdr import _uniform_cdr, cdr_to_arrays
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu
    rng = np.random.default_rng(13)
    msgs = []
    for i in range(50):
        m = Imu()
        m.header.frame_id = frame
        m.header.stamp.sec = -2 if i == 3 else 1_700_000_000 + i  # int32: negative too
        m.header.stamp.nanosec = i * 19_999_999
        (m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z,
         m.linear_acceleration.x, m.linear_acceleration.y,
         m.linear_acceleration.z) = rng.normal(size=6).tolist()
        msgs.append(m)
    blobs = [serialize_message(m) for m in msgs]
    t_ref, d_ref = imus_to_arrays(msgs)
    assert _uniform_cdr(blobs) is not None  # the one-view path is the one tested
    t, d = cdr_to_arrays(blobs)
    np.testing.assert_array_equal(t, t_ref)
    np.testing.assert_array_equal(d, d_ref)
    # nanosec 1e9 in the bytes (rclpy refuses to build it): NaN, as the row decoder gives
    damaged = bytearray(blobs[7])
    damaged[8:12] = (1_000_000_000).to_bytes(4, 'little')
    blobs[7] = bytes(damaged)
    rows = np.frombuffer(b''.join(blobs), np.uint8).reshape(len(blobs), -1)
    ok, t_rows, d_rows = _decode_rows(rows, ros1=False)
    t, d = cdr_to_arrays(blobs)
    assert ok.all() and np.isnan(t[7])
    np.testing.assert_array_equal(t, t_rows)
    np.testing.assert_array_equal(d, d_rows)
    # one big-endian message: the general path, the same numbers for every message
    big = _rosbags_imu(int(msgs[9].header.stamp.sec), int(msgs[9].header.stamp.nanosec),
                       d_ref[9, :3], d_ref[9, 3:], frame_id=frame)
    blobs[9] = bytes(JAZZY.serialize_cdr(big, IMU, little_endian=False))
    assert len(blobs[9]) == len(blobs[0]) and _uniform_cdr(blobs) is None
    t, d = cdr_to_arrays(blobs)
    np.testing.assert_array_equal(t[9], t_ref[9])
    np.testing.assert_array_equal(d, d_rows)


@pytest.mark.ros
def test_covariance_diagonals_patched_in_bytes_as_rclpy_reads_them():
    """
    set_covariance_diagonals: rclpy deserializes exactly the intended messages.

    Diagonals set, off-diagonals and orientation kept, a -1 ("not provided") matrix and NaN
    entries left alone, order and every other field unchanged, over several frame_id lengths.
    """
    from imu_allan.formats.imu_cdr import set_covariance_diagonals
    from rclpy.serialization import deserialize_message, serialize_message
    from sensor_msgs.msg import Imu
    rng = np.random.default_rng(13)
    msgs = []
    for i, frame in enumerate(['imu_link', 'a', 'imu', 'base_imu_frame_0'] * 5):
        m = Imu()
        m.header.frame_id = frame
        m.header.stamp.sec, m.header.stamp.nanosec = 1_700_000_000 + i, 1000 * i
        m.orientation_covariance = [-1.0] + [0.0] * 8
        m.angular_velocity_covariance = rng.normal(size=9).tolist()
        m.linear_acceleration_covariance = rng.normal(size=9).tolist()
        if i % 4 == 3:
            m.linear_acceleration_covariance[0] = -1.0
        m.angular_velocity.x = float(i)
        msgs.append(m)
    variances = [1e-4, 2e-4, np.nan, 3e-3, 4e-3, 5e-3]
    blobs = set_covariance_diagonals([serialize_message(m) for m in msgs], variances)
    for i, (m, blob) in enumerate(zip(msgs, blobs)):
        got = deserialize_message(blob, Imu)
        want_w = np.array(m.angular_velocity_covariance)
        want_w[[0, 4]] = variances[:2]
        want_a = np.array(m.linear_acceleration_covariance)
        if i % 4 != 3:
            want_a[[0, 4, 8]] = variances[3:]
        np.testing.assert_array_equal(got.angular_velocity_covariance, want_w)
        np.testing.assert_array_equal(got.linear_acceleration_covariance, want_a)
        assert list(got.orientation_covariance) == list(m.orientation_covariance)
        assert (got.header.frame_id, got.header.stamp.nanosec, got.angular_velocity.x) == \
            (m.header.frame_id, m.header.stamp.nanosec, m.angular_velocity.x)


def _encoded(n, frame_id, seed):
    rng = np.random.default_rng(seed)
    t = 1.7e9 + np.sort(rng.uniform(0.0, 100.0, n))
    rows, stamps = encode_imu(t, rng.normal(size=(n, 6)), frame_id)
    return rows, np.asarray(stamps, dtype=np.int64)


@pytest.mark.parametrize('capacity', [0, 50, 10_000])
def test_collector_capacity_and_order(capacity):
    """
    Reserved arrays, exceeded or not, give what concatenation gives, in receive-time order.

    Parts arrive out of time order (the second batch is earlier), one message has a
    nanosecond field of 1e9 (damaged: dropped and counted), and the earliest message names
    the frame id; a capacity of 50 is exceeded by the 120 messages, 10 000 is not.
    """
    rows_a, times_a = _encoded(80, 'late', 1)
    rows_b, times_b = _encoded(40, 'early', 2)
    times_b -= 10**12  # 1000 s earlier
    rows_b = rows_b.copy()
    rows_b[7, 8:12] = np.frombuffer(np.uint32(1_000_000_000).tobytes(), np.uint8)
    got = Collector(False, deserialize, capacity=capacity)
    got.add_rows(times_a, rows_a)
    got.add_rows(times_b, rows_b)
    t, data = got.result()
    keep = np.ones(40, bool)
    keep[7] = False
    _, t_b, d_b = _decode_rows(rows_b, ros1=False)
    _, t_a, d_a = _decode_rows(rows_a, ros1=False)
    assert np.array_equal(t, np.concatenate([t_b[keep], t_a]))
    assert np.array_equal(data, np.concatenate([d_b[keep], d_a]))
    assert got.undecodable == 1 and 'nanosecond' in got.warnings()[0]
    assert got.frame_id == 'early'
    generic = Collector(False, deserialize, force_generic=True)
    generic.add_rows(times_b, rows_b)
    assert generic.undecodable == 1 and np.array_equal(generic.result()[0], t_b[keep])


def test_frame_id_of_both_layouts():
    """The frame id from a message's bytes, CDR (with its NUL) and ROS 1, and '' when cut."""
    for ros1 in (False, True):
        rows, _ = encode_imu(np.array([1.7e9]), np.zeros((1, 6)), 'imu_link', ros1=ros1)
        raw = rows[0].tobytes()
        assert frame_id_of(raw, ros1) == 'imu_link'
        assert frame_id_of(raw[:20], ros1) == ''
