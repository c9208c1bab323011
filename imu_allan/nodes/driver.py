"""driver: LORD MicroStrain 3DM-GX3-25 (single-byte protocol) -> sensor_msgs/Imu.

A thin node around :class:`imu_allan.io.serial_link.Gx3Session`, which runs in a thread:
it opens the port (retrying with back-off), configures the device, frames the byte stream,
detects dropped packets from timer gaps, stalls and vanished ports, and recovers from them.
Each read of the port (every ``read_period``) gives one batch, decoded with numpy and
serialized at once (:class:`CdrPacker`); the session thread publishes it directly (rclpy
publishers are thread-safe), so the executor only wakes for /diagnostics and parameters.

Published (names relative, sensor-data QoS with QoS overrides enabled):

* ``imu/data_raw`` (sensor_msgs/Imu): angular velocity rad/s, linear acceleration m/s^2
  (device g times ``gravity``), orientation not provided (orientation_covariance[0] = -1);
* ``imu/data`` (sensor_msgs/Imu, orientation modes only): the same plus the orientation
  quaternion of the device's orientation matrix (sensor frame in the device's
  north-east-down earth frame);
* ``imu/mag`` (sensor_msgs/MagneticField, mag modes only): tesla (device gauss * 1e-4);
* ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) once per ``diagnostics_period``.

Stamps are the device timer mapped to the ROS clock (method: see
:mod:`imu_allan.io.serial_link` and ``docs/driver.md``) plus ``time_offset``.
"""

import math
import struct
import sys

import numpy as np

from ..io import gx3_protocol as p
from ..io.errors import InputError
from ..io.serial_link import check_rate, Gx3Session, MODES
from .node_utils import descriptor, diagnostic_status, float_range, node_main

DESCRIPTION = ('Reads a LORD MicroStrain 3DM-GX3-25 over a serial port (single-byte '
               'protocol) and publishes imu/data_raw, imu/data (orientation modes), imu/mag '
               '(mag modes) and /diagnostics. Survives unplugging, stalls and garbage.')

#: (name, default, description, runtime-changeable)
PARAMETERS = [
    ('port', '/dev/ttyACM0', 'serial port of the device (a stable /dev/serial/by-id/... '
                             'path survives re-enumeration)', False),
    ('baud', 115200, 'link baud rate: 115200, 230400, 460800 or 921600 (the device is '
                     'switched with command 0xD9 if it answers only at 115200)', False),
    ('rate_hz', 100.0, 'output rate, Hz: 1000/decimation, decimation 1..1000; rates the baud '
                       'cannot carry are refused (115200: 250 Hz, 230400: 333 Hz, 460800: '
                       '500 Hz, 921600: 1000 Hz for 31-byte records)', False),
    ('mode', 'accel_rate', 'records streamed: ' + ', '.join(
        f'{m} (0x{c:02X})' for m, c in MODES.items()), False),
    ('frame_id', 'imu_link', 'frame_id of the published messages', False),
    ('gravity', 9.80665, 'm/s^2 per g for the accelerometer conversion', False),
    ('angular_velocity_stddev', 0.0058, 'per-sample std of the angular velocity, rad/s '
                                        '(diagonal of its covariance; 0 = unknown)', True),
    ('linear_acceleration_stddev', 0.0083, 'per-sample std of the acceleration, m/s^2 '
                                           '(diagonal of its covariance; 0 = unknown)', True),
    ('orientation_stddev', 0.035, 'std of the orientation, rad (imu/data only)', True),
    ('magnetic_field_stddev', 0.0, 'std of the magnetic field, T (0 = unknown)', True),
    ('time_offset', 0.0, 'seconds added to every stamp (known transport latency, negative '
                         'to move stamps earlier)', True),
    ('stall_timeout', 1.0, 'seconds without a record before the device is reconfigured '
                           '(at least 3 output periods are used)', False),
    ('record_raw', '', 'if set, append the raw received byte stream to this file '
                       '(analyze --format gx3raw reads it)', False),
    ('read_period', 0.005, 'seconds between reads of the port (each read is published as '
                           'one batch: latency vs CPU)', False),
    ('diagnostics_period', 1.0, 'seconds between /diagnostics messages', False),
]
_RUNTIME = {name for name, _, _, dynamic in PARAMETERS if dynamic}
_FLOAT_RANGES = {
    'rate_hz': (1.0, 1000.0), 'gravity': (9.7, 9.9), 'angular_velocity_stddev': (0.0, 10.0),
    'linear_acceleration_stddev': (0.0, 100.0), 'orientation_stddev': (0.0, 10.0),
    'magnetic_field_stddev': (0.0, 1.0), 'time_offset': (-10.0, 10.0),
    'stall_timeout': (0.1, 60.0), 'read_period': (0.001, 0.1),
    'diagnostics_period': (0.1, 60.0),
}


def _check_float(name, value):
    """Return ``value`` as float if it is a number inside the parameter's range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(name, f'must be a number, got {value!r}')
    value = float(value)
    low, high = _FLOAT_RANGES[name]
    if not (math.isfinite(value) and low <= value <= high):
        raise InputError(name, f'{value:g} is outside [{low:g}, {high:g}]')
    return value


def split_stamps(stamps_ns):
    """Integer nanoseconds -> (sec, nanosec) lists for builtin_interfaces/Time."""
    ns = np.asarray(stamps_ns, dtype=np.int64)
    sec = ns // 1_000_000_000
    return sec.tolist(), (ns - sec * 1_000_000_000).tolist()


_SENTINEL_STAMP = (0x7A5A5A01, 0x3A5A5A02)


def _sentinel(k):
    """A float64 with a distinctive bit pattern (found again in serialized bytes)."""
    return struct.unpack('<d', struct.pack('<Q', 0x1A2B3C4D5E6F0100 + k))[0]


def _find_once(raw, pattern):
    i = raw.find(pattern)
    if i < 0 or raw.find(pattern, i + 1) >= 0:
        raise RuntimeError('CDR layout not recognised')
    return i


class CdrPacker:
    """Serialize a batch of messages by patching a CDR template with numpy.

    The template is the configured message (frame_id, covariances) serialized once by rclpy
    with sentinel values in the fields that change per message (stamp and float64 vectors);
    the sentinels locate those fields.  ``pack`` then writes a whole batch at once, and each
    message is published as bytes (rclpy ``publish`` accepts serialized messages).  Values
    are the same float64 numbers that would have been assigned to the message fields.
    """

    def __init__(self, msg, vectors):
        """``vectors``: name -> (sub-message, attribute letters), e.g. ('...', 'xyz')."""
        from rclpy.serialization import serialize_message
        msg.header.stamp.sec, msg.header.stamp.nanosec = _SENTINEL_STAMP
        k = 0
        firsts = {}
        for name, (obj, attrs) in vectors.items():
            firsts[name] = (k, len(attrs))
            for attr in attrs:
                setattr(obj, attr, _sentinel(k))
                k += 1
        raw = serialize_message(msg)
        if raw[:2] != b'\x00\x01':
            raise RuntimeError('expected little-endian CDR')
        self.size = len(raw)
        self.template = np.frombuffer(raw, dtype=np.uint8)
        self.stamp = _find_once(raw, struct.pack('<iI', *_SENTINEL_STAMP))
        self.offsets = {}
        for name, (first, n) in firsts.items():
            pattern = b''.join(struct.pack('<d', _sentinel(first + j)) for j in range(n))
            self.offsets[name] = (_find_once(raw, pattern), n)

    def pack(self, secs, nsecs, **vectors):
        """Return ``(bytes of n messages back to back, message size)``."""
        n = len(secs)
        out = np.empty((n, self.size), dtype=np.uint8)
        out[:] = self.template
        stamp = np.empty((n, 2), dtype='<u4')
        stamp[:, 0] = np.asarray(secs, dtype=np.int64).astype('<i4').view('<u4')
        stamp[:, 1] = nsecs
        out[:, self.stamp:self.stamp + 8] = stamp.view(np.uint8).reshape(n, 8)
        for name, values in vectors.items():
            off, k = self.offsets[name]
            block = np.ascontiguousarray(values, dtype='<f8').reshape(n, k)
            out[:, off:off + 8 * k] = block.view(np.uint8).reshape(n, 8 * k)
        return out.tobytes(), self.size


def _node_class():
    from diagnostic_msgs.msg import DiagnosticArray
    from rcl_interfaces.msg import SetParametersResult
    from rclpy.node import Node
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.qos_overriding_options import QoSOverridingOptions
    from sensor_msgs.msg import Imu, MagneticField

    class DriverNode(Node):
        """The ROS side: parameters, publishers, batch publishing, diagnostics."""

        def __init__(self):
            super().__init__('driver')
            values = {}
            for name, default, text, dynamic in PARAMETERS:
                kwargs = {}
                if name in _FLOAT_RANGES:
                    # Dynamic typing so that "-p rate_hz:=200" (an integer) is accepted.
                    kwargs['dynamic_typing'] = True
                    kwargs['floating_point_range'] = float_range(*_FLOAT_RANGES[name])
                if name == 'baud':
                    kwargs['additional_constraints'] = 'one of ' + ', '.join(
                        map(str, p.BAUD_RATES))
                if name == 'mode':
                    kwargs['additional_constraints'] = 'one of ' + ', '.join(MODES)
                values[name] = self.declare_parameter(
                    name, default, descriptor(text, read_only=not dynamic, **kwargs)).value
            cfg = self._validate(values)
            self.cfg = cfg
            self.decimation, _ = check_rate(cfg['rate_hz'], cfg['baud'], cfg['mode'])
            self.code = MODES[cfg['mode']]
            qos = qos_profile_sensor_data
            overrides = QoSOverridingOptions.with_default_policies()
            self.pub_raw = self.create_publisher(Imu, 'imu/data_raw', qos,
                                                 qos_overriding_options=overrides)
            self.orientation = 'orientation' in cfg['mode']
            self.has_mag = 'mag' in cfg['mode']
            self.pub_data = self.create_publisher(
                Imu, 'imu/data', qos, qos_overriding_options=overrides) \
                if self.orientation else None
            self.pub_mag = self.create_publisher(
                MagneticField, 'imu/mag', qos, qos_overriding_options=overrides) \
                if self.has_mag else None
            self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
            self.msg_raw, self.msg_data = Imu(), Imu()
            self.msg_mag = MagneticField()
            for msg in (self.msg_raw, self.msg_data, self.msg_mag):
                msg.header.frame_id = cfg['frame_id']
            self._set_covariances()
            self.add_on_set_parameters_callback(self._on_set)
            stall = max(cfg['stall_timeout'], 3.0 * self.decimation / p.BASE_RATE_HZ)
            try:
                self.session = Gx3Session(
                    cfg['port'], cfg['baud'], cfg['mode'], cfg['rate_hz'],
                    on_batch=self._on_batch, poll_interval=cfg['read_period'],
                    clock=self._now, log=self._log, stall_timeout=stall,
                    record_raw=cfg['record_raw'] or None)
            except OSError as exc:
                raise InputError(cfg['record_raw'], f'cannot open for writing '
                                                    f'({exc.strerror})') from None
            self.published = 0
            self._diag_last = (self._now(), 0)
            self.create_timer(cfg['diagnostics_period'], self._diagnostics)
            self.session.start()

        # ------------------------------------------------------------ parameters
        def _validate(self, values):
            cfg = dict(values)
            for name in _FLOAT_RANGES:
                cfg[name] = _check_float(name, values[name])
            if not isinstance(values['baud'], int) or values['baud'] not in p.BAUD_RATES:
                raise InputError('baud', f'{values["baud"]!r} is not one of '
                                         f'{", ".join(map(str, p.BAUD_RATES))}')
            if not isinstance(values['port'], str) or not values['port']:
                raise InputError('port', 'must be a non-empty device path')
            if not isinstance(values['frame_id'], str) or not values['frame_id']:
                raise InputError('frame_id', 'must be a non-empty string')
            if values['mode'] not in MODES:
                raise InputError('mode', f'{values["mode"]!r} is not one of '
                                         f'{", ".join(MODES)}')
            try:
                decimation, _ = check_rate(cfg['rate_hz'], cfg['baud'], cfg['mode'])
            except ValueError as exc:
                raise InputError('rate_hz', str(exc)) from None
            actual = p.rate_for_decimation(decimation)
            if abs(actual - cfg['rate_hz']) > 1e-6 * actual:
                self.get_logger().warning(
                    f'rate_hz {cfg["rate_hz"]:g} is not 1000/integer: the device runs at '
                    f'{actual:.6g} Hz (decimation {decimation})')
            return cfg

        def _on_set(self, params):
            Result = SetParametersResult
            updates = {}
            for param in params:
                if param.name not in _RUNTIME:
                    continue    # read-only ones are refused by rclpy; QoS overrides pass
                try:
                    updates[param.name] = _check_float(param.name, param.value)
                except InputError as exc:
                    return Result(successful=False, reason=str(exc))
            self.cfg.update(updates)
            self._set_covariances()
            return Result(successful=True)

        def _set_covariances(self):
            cfg = self.cfg

            def diag(std):
                var = float(std) ** 2
                return [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var]

            for msg in (self.msg_raw, self.msg_data):
                msg.angular_velocity_covariance = diag(cfg['angular_velocity_stddev'])
                msg.linear_acceleration_covariance = diag(cfg['linear_acceleration_stddev'])
            self.msg_raw.orientation_covariance = [-1.0] + [0.0] * 8
            self.msg_data.orientation_covariance = diag(cfg['orientation_stddev'])
            self.msg_mag.magnetic_field_covariance = diag(cfg['magnetic_field_stddev'])
            self.pack_raw = CdrPacker(self.msg_raw, {
                'angular_velocity': (self.msg_raw.angular_velocity, 'xyz'),
                'linear_acceleration': (self.msg_raw.linear_acceleration, 'xyz')})
            self.pack_data = CdrPacker(self.msg_data, {
                'angular_velocity': (self.msg_data.angular_velocity, 'xyz'),
                'linear_acceleration': (self.msg_data.linear_acceleration, 'xyz'),
                'orientation': (self.msg_data.orientation, 'xyzw')})
            self.pack_mag = CdrPacker(self.msg_mag, {
                'magnetic_field': (self.msg_mag.magnetic_field, 'xyz')})

        # ------------------------------------------------------------ helpers
        def _now(self):
            return self.get_clock().now().nanoseconds * 1e-9

        def _log(self, level, text):
            # One call site per severity (rclpy refuses to change it at a call site).
            logger = self.get_logger()
            if level == 'info':
                logger.info(text)
            elif level == 'warn':
                logger.warning(text)
            else:
                logger.error(text)

        # ------------------------------------------------------------ publishing
        def _on_batch(self, code, rec, stamps):
            """Session thread: publish one batch (stamps in integer ns)."""
            offset_ns = int(round(self.cfg['time_offset'] * 1e9))
            try:
                self._publish_batch(rec, stamps + offset_ns)
            except Exception:
                if self.context.ok():
                    raise
                # Shutting down (signal): the last batch has nowhere to go.

        def _publish_batch(self, rec, stamps):
            secs, nsecs = split_stamps(stamps)
            gyro = rec['gyro'].astype(np.float64)
            accel = rec['accel'].astype(np.float64) * self.cfg['gravity']
            out = [(self.pub_raw, self.pack_raw.pack(
                secs, nsecs, angular_velocity=gyro, linear_acceleration=accel))]
            if self.orientation:
                out.append((self.pub_data, self.pack_data.pack(
                    secs, nsecs, angular_velocity=gyro, linear_acceleration=accel,
                    orientation=p.matrix_to_quaternion(rec['matrix']))))
            if self.has_mag:
                out.append((self.pub_mag, self.pack_mag.pack(
                    secs, nsecs,
                    magnetic_field=rec['mag'].astype(np.float64) * p.GAUSS_TO_TESLA)))
            # Per message only a slice and a publish of ready CDR bytes.
            for publisher, (raw, size) in out:
                publish = publisher.publish
                for start in range(0, len(raw), size):
                    publish(raw[start:start + size])
            self.published += len(secs)

        # ------------------------------------------------------------ diagnostics
        def _diagnostics(self):
            session = self.session
            st, ps = session.stats, session.parser.stats
            now = self._now()
            then, records_then = self._diag_last
            rate = (st.records - records_then) / (now - then) if now > then else 0.0
            self._diag_last = (now, st.records)
            device_rate = p.rate_for_decimation(self.decimation)
            state = session.state
            if state == 'streaming':
                if rate < 0.9 * device_rate and st.records > records_then:
                    level, message = 1, f'streaming below the requested rate ({rate:.1f} Hz)'
                else:
                    level, message = 0, f'streaming at {rate:.1f} Hz'
            elif state in ('configuring', 'starting'):
                level, message = 1, state
            else:
                level, message = 2, f'{state}: {session.last_error}'
            values = {
                'port': self.cfg['port'], 'baud': session.link.baud, 'mode': self.cfg['mode'],
                'rate_requested_hz': float(self.cfg['rate_hz']),
                'rate_device_hz': float(device_rate), 'rate_achieved_hz': float(rate),
                'packets': st.records, 'published': self.published,
                'checksum_failures': ps.bad_checksums, 'resyncs': ps.resyncs,
                'rejected_bytes': ps.rejected_bytes, 'dropped_packets': st.dropped,
                'stalls': st.stalls, 'reconnects': st.reconnects,
                'setup_failures': st.setup_failures, 'timer_rollovers': st.rollovers,
                'timer_resets': st.timer_resets, 'time_jumps': session.sync.jumps,
                'device_model': session.model, 'device_serial': session.serial_number,
                'firmware': session.firmware, 'state': state,
                'last_error': session.last_error,
            }
            arr = DiagnosticArray()
            arr.header.stamp = self.get_clock().now().to_msg()
            arr.status.append(diagnostic_status(
                f'{self.get_name()}: 3DM-GX3-25 IMU', level, message,
                hardware_id=session.serial_number or self.cfg['port'], values=values))
            self.pub_diag.publish(arr)

        def close(self):
            """Stop the session thread (it stops continuous mode and closes the port)."""
            self.session.stop()

    return DriverNode


def main(args=None):
    """Entry point of ``driver``."""
    node_main('driver', DESCRIPTION, PARAMETERS, lambda: _node_class()(), args)


if __name__ == '__main__':
    sys.exit(main())
