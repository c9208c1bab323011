"""
The driver's batch path publishes, byte for byte, what its record-by-record path publishes.

A real 3DM-GX3-25 capture (0xCB accel + rate + mag records among 0xCF packets, plus the
cut-outs with bad checksums, a timer rollover and a timer reset), with junk and a truncated
record added, is written into a real pseudo-terminal in chunks of random size, so records are
split across reads.  A :class:`Gx3Session` reads it through a real :class:`SerialLink` and
hands each batch to a real :class:`DriverNode`'s serializer, once with the vectorized path
and once with every batch taken record by record (the path of batches with a rollover or a
reset).  The same reads and clock readings go in; the same bytes must come out, and every
message must equal rclpy's own serialization of a message built from that record alone.
"""

import os
import time

from conftest import SHARED_DATA
from device.test_serial_link import same_message
from imu_allan.device import gx3_protocol as p
from imu_allan.device.gx3_stream import parse_bytes
from imu_allan.device.serial_link import Gx3Session, SessionHooks
import numpy as np
import pytest

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')

DATA = SHARED_DATA / 'gx3_25_captures'
CAPTURES = ('20140313_191853.3dmgx3.log', '20140313_191853_bad_chksum.3dmgx3.log',
            '20140313_191853_rollover.3dmgx3.log', '20140313_191853_timer_reset.3dmgx3.log')
G = 9.80665


def captured_stream(rng):
    """Return the captures back to back, with junk bursts and one truncated record inserted."""
    data = b''.join((DATA / name).read_bytes() for name in CAPTURES)
    packets, _ = parse_bytes(data)
    junk = bytes([0x00, 0xCB, 0x17, 0xCF, 0x42]) * 3      # header-like bytes inside junk
    record = next(x for x in packets if x[0] == p.ACCEL_RATE_MAG)
    parts, start = [], 0
    for pos in sorted(rng.choice(len(data), size=6, replace=False).tolist()) + [len(data)]:
        parts.append(data[start:pos])
        parts.append(junk[:int(rng.integers(1, len(junk)))])
        start = pos
    parts.insert(3, record[:20])                            # a record cut short
    del parts[-1]
    return b''.join(parts)


@pytest.fixture(scope='module')
def driver_node(ros_context):
    """Yield a DriverNode (10 Hz accel_rate_mag, as the capture) with its session stopped."""
    from imu_allan.nodes.driver import DriverNode
    from rclpy.parameter import Parameter
    node = DriverNode(context=ros_context, parameter_overrides=[
        Parameter('port', value='/nonexistent/gx3'), Parameter('rate_hz', value=10.0),
        Parameter('mode', value='accel_rate_mag'), Parameter('gravity', value=G)])
    node.close()
    yield node
    node.destroy_node()


def replay(node, stream, sizes, vectorized):
    """
    Feed ``stream`` through a real pty in chunks of ``sizes``; return (messages, session).

    Each chunk is written, the test waits until the port holds all of it, then the session
    reads once: the reads, and the clock readings (a fixed function of the read count), are
    the same in every run.  ``messages`` is one list of CDR bytes per topic.
    """
    master, slave = os.openpty()
    batches = []
    reads = [0]

    def clock():
        reads[0] += 1
        return 1_700_000_000.25 + 0.05 * reads[0] + 1e-4 * (reads[0] % 7)

    session = Gx3Session(os.ttyname(slave), 115200, 'accel_rate_mag', 10.0,
                         SessionHooks(lambda code, rec, stamps: batches.append(
                             node.serialize_batch(rec, stamps)), clock=clock))
    session.vectorized = vectorized
    try:
        session.link.open()
        start = 0
        for size in sizes:
            chunk = stream[start:start + size]
            start += size
            os.write(master, chunk)
            end = time.monotonic() + 5.0
            while session.link.serial.in_waiting < len(chunk) and time.monotonic() < end:
                time.sleep(0.001)
            assert session.link.serial.in_waiting == len(chunk)
            session._pump()
    finally:
        session.link.close()
        os.close(master)
        os.close(slave)
    topics = [[], []]
    for batch in batches:
        for messages, (_, raw, size) in zip(topics, batch):
            messages += [raw[i:i + size] for i in range(0, len(raw), size)]
    return topics, session


@pytest.mark.skipif(not DATA.is_dir(), reason=f'real GX3-25 captures not found at {DATA}')
def test_batch_path_equals_record_by_record_on_a_real_capture(driver_node):
    """
    Same CDR bytes on imu/data_raw and imu/mag from both paths; nothing lost or reordered.

    Every intact 0xCB record of the stream is published once, in stream order, and each
    message equals rclpy's serialization of an Imu / MagneticField set field by field from
    that record (struct-decoded) and its stamp.  Exact comparison of bytes and counters.
    """
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Imu, MagneticField
    rng = np.random.default_rng(7)
    stream = captured_stream(rng)
    sizes = rng.integers(1, 120, size=len(stream))
    sizes = sizes[:np.searchsorted(np.cumsum(sizes), len(stream)) + 1]
    (raw_fast, mag_fast), fast = replay(driver_node, stream, sizes, vectorized=True)
    (raw_each, mag_each), each = replay(driver_node, stream, sizes, vectorized=False)
    assert raw_fast == raw_each and mag_fast == mag_each
    for key in ('records', 'dropped', 'rollovers', 'timer_resets'):
        assert getattr(fast.stats, key) == getattr(each.stats, key), key
    assert fast.sync.jumps == each.sync.jumps
    assert fast.stats.rollovers >= 1 and fast.stats.timer_resets >= 1
    assert fast.parser.stats.bad_checksums >= 2 and fast.parser.stats.resyncs >= 3

    packets, _ = parse_bytes(stream)
    records = [x for x in packets if x[0] == p.ACCEL_RATE_MAG]
    assert len(raw_fast) == len(mag_fast) == len(records) > 80
    template = driver_node.msg_raw
    for blob, mag_blob, packet in zip(raw_fast, mag_fast, records):
        fields = p.decode_record(packet).fields
        sec = int.from_bytes(blob[4:8], 'little', signed=True)
        nanosec = int.from_bytes(blob[8:12], 'little')
        msg = Imu()
        msg.header.frame_id = template.header.frame_id
        msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
        msg.orientation_covariance = template.orientation_covariance
        msg.angular_velocity_covariance = template.angular_velocity_covariance
        msg.linear_acceleration_covariance = template.linear_acceleration_covariance
        (msg.angular_velocity.x, msg.angular_velocity.y,
         msg.angular_velocity.z) = fields['gyro']
        (msg.linear_acceleration.x, msg.linear_acceleration.y,
         msg.linear_acceleration.z) = (a * G for a in fields['accel'])
        assert same_message(serialize_message(msg), blob)
        mag = MagneticField()
        mag.header = msg.header
        mag.magnetic_field_covariance = driver_node.msg_mag.magnetic_field_covariance
        mag.magnetic_field.x, mag.magnetic_field.y, mag.magnetic_field.z = (
            m * p.GAUSS_TO_TESLA for m in fields['mag'])
        assert same_message(serialize_message(mag), mag_blob)
