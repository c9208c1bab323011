"""
driver: LORD MicroStrain 3DM-GX3-25 (single-byte protocol) -> sensor_msgs/Imu.

A thin node around :class:`imu_allan.device.serial_link.Gx3Session`, which runs in a thread:
it opens the port (retrying with back-off), configures the device, frames the byte stream,
detects dropped packets from timer gaps, stalls and vanished ports, and recovers from them.
Each read of the port (every ``read_period``) gives one batch, decoded with numpy and
serialized at once (:class:`CdrPacker`); the session thread publishes it directly (rclpy
publishers are thread-safe), so the executor only wakes for /diagnostics and parameters.

Published (names relative, sensor-data QoS with QoS overrides enabled; content and units in
docs/driver.md, section Topics): ``imu/data_raw`` (sensor_msgs/Imu, no orientation),
``imu/data`` (orientation modes: plus the quaternion of the device's orientation matrix),
``imu/mag`` (mag modes; tesla), ``imu/temperature`` (unless ``temperature_period`` is 0: the
board deg C polled with 0xD1, DCP-GX3 Eq. 15) and ``/diagnostics`` (with the device's
processing as confirmed by 0xDB).

Stamps are the device timer mapped to the ROS clock (method: see
:mod:`imu_allan.device.serial_link` and ``docs/driver.md``) plus ``time_offset``.
"""

import sys

from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Imu, MagneticField, Temperature

from .common import (
    apply_changes,
    declare_parameter_table,
    diagnostic_status,
    log,
    node_main,
    Param,
    sensor_publisher,
    validate_on_set,
)
from ..device import gx3_protocol as p
from ..device.serial_link import check_rate, Gx3Session, MODES, SessionHooks, SessionOptions
from ..errors import InputError
from ..formats.imu_cdr import CdrPacker

DESCRIPTION = ('Reads a LORD MicroStrain 3DM-GX3-25 over a serial port (single-byte '
               'protocol) and publishes imu/data_raw, imu/data (orientation modes), imu/mag '
               '(mag modes), imu/temperature and /diagnostics. Survives unplugging, stalls and '
               'garbage.')

#: The parameter table (nodes.common.Param); only the covariances and time_offset change at run
#: time, everything else configures the device once.
PARAMETERS = [
    Param('port', '/dev/ttyACM0', 'serial port of the device (a stable /dev/serial/by-id/... '
                                  'path survives re-enumeration)', read_only=True),
    Param('baud', 115200, 'link baud rate (the device is switched with command 0xD9 if it '
                          'answers only at 115200)', read_only=True, choices=p.BAUD_RATES),
    Param('rate_hz', 100.0, 'output rate, Hz: 1000/decimation, decimation 1..1000; rates the '
                            'baud cannot carry are refused (115200: 250 Hz, 230400: 333 Hz, '
                            '460800: 500 Hz, 921600: 1000 Hz for 31-byte records)',
          (1.0, 1000.0), read_only=True),
    Param('filter_window', 15, 'gyro/accel moving-average window of the device, samples of '
                               'its 1 kHz internal stream (0xDB; factory 15 = 15 ms): each '
                               'output is the mean of the last filter_window of them; shown on '
                               '/diagnostics, give the allan node filter_window / 1000 as '
                               'filter_window_s', (1, 32), read_only=True),
    Param('mode', 'accel_rate', 'records streamed: ' + ', '.join(
        f'{m} (0x{c:02X})' for m, c in MODES.items()), read_only=True, choices=tuple(MODES)),
    Param('frame_id', 'imu_link', 'frame_id of the published messages', read_only=True),
    Param('gravity', 9.80665, 'm/s^2 per g for the accelerometer conversion', (9.7, 9.9),
          read_only=True),
    Param('angular_velocity_stddev', 0.0058, 'per-sample std of the angular velocity, rad/s '
                                             '(diagonal of its covariance; 0 = unknown)',
          (0.0, 10.0)),
    Param('linear_acceleration_stddev', 0.0083, 'per-sample std of the acceleration, m/s^2 '
                                                '(diagonal of its covariance; 0 = unknown)',
          (0.0, 100.0)),
    Param('orientation_stddev', 0.035, 'std of the orientation, rad (imu/data only)',
          (0.0, 10.0)),
    Param('magnetic_field_stddev', 0.0, 'std of the magnetic field, T (0 = unknown)',
          (0.0, 1.0)),
    Param('time_offset', 0.0, 'seconds added to every stamp (known transport latency, negative '
                              'to move stamps earlier)', (-10.0, 10.0)),
    Param('stall_timeout', 1.0, 'seconds without a record before the device is reconfigured '
                                '(at least 3 output periods are used)', (0.1, 60.0),
          read_only=True),
    Param('record_raw', '', 'if set, append the raw received byte stream to this file '
                            '(analyze --format gx3raw reads it)', read_only=True),
    Param('read_period', 0.01, 'seconds between reads of the port (each read is published as '
                               'one batch: delivery latency vs CPU; stamps do not depend on '
                               'it)', (0.001, 0.1), read_only=True),
    Param('diagnostics_period', 1.0, 'seconds between /diagnostics messages', (0.1, 60.0),
          read_only=True),
    Param('temperature_period', 1.0, 'seconds between temperature polls (0xD1, answered '
                                     'between data records, published on imu/temperature '
                                     'in deg C); 0 = off', (0.0, 3600.0), read_only=True),
]


class DriverNode(Node):
    """The ROS side: parameters, publishers, batch publishing, diagnostics."""

    def __init__(self, **node_options):
        """Declare the parameters, open the publishers, start the session thread."""
        super().__init__('driver', **node_options)
        self.cfg = cfg = declare_parameter_table(self, PARAMETERS)
        self.decimation = self._decimation(cfg)
        self.orientation = 'orientation' in cfg['mode']
        self.has_mag = 'mag' in cfg['mode']
        self.pub_raw = sensor_publisher(self, Imu, 'imu/data_raw')
        self.pub_data = sensor_publisher(self, Imu, 'imu/data') if self.orientation else None
        self.pub_mag = sensor_publisher(self, MagneticField, 'imu/mag') if self.has_mag else None
        self.pub_temperature = (sensor_publisher(self, Temperature, 'imu/temperature')
                                if cfg['temperature_period'] > 0 else None)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.msg_raw, self.msg_data = Imu(), Imu()
        self.msg_mag = MagneticField()
        for msg in (self.msg_raw, self.msg_data, self.msg_mag):
            msg.header.frame_id = cfg['frame_id']
        self._set_covariances()
        self.add_on_set_parameters_callback(validate_on_set(self.cfg, PARAMETERS))
        self.add_post_set_parameters_callback(self._post_set)
        self._clock_handle = self.get_clock().handle
        stall = max(cfg['stall_timeout'], 3.0 * self.decimation / p.BASE_RATE_HZ)
        try:
            self.session = Gx3Session(
                cfg['port'], cfg['baud'], cfg['mode'], cfg['rate_hz'],
                SessionHooks(self._on_batch, self._now, lambda level, text: log(self, level, text),
                             self._on_temperature),
                SessionOptions(stall_timeout=stall, poll_interval=cfg['read_period'],
                               temperature_period=cfg['temperature_period'],
                               filter_window=cfg['filter_window'],
                               record_raw=cfg['record_raw'] or None))
        except OSError as exc:
            raise InputError(cfg['record_raw'], f'cannot open for writing '
                                                f'({exc.strerror})') from None
        self.published = 0
        self._diag_last = (self._now(), 0)
        self.create_timer(cfg['diagnostics_period'], self._diagnostics)
        self.session.start()

    # ------------------------------------------------------------ parameters
    def _decimation(self, cfg):
        """Return the decimation of ``rate_hz``; InputError if baud and mode cannot carry it."""
        try:
            decimation, _ = check_rate(cfg['rate_hz'], cfg['baud'], cfg['mode'])
        except ValueError as exc:
            raise InputError('rate_hz', str(exc)) from None
        actual = p.rate_for_decimation(decimation)
        if abs(actual - cfg['rate_hz']) > 1e-6 * actual:
            self.get_logger().warning(
                f'rate_hz {cfg["rate_hz"]:g} is not 1000/integer: the device runs at '
                f'{actual:.6g} Hz (decimation {decimation})')
        return decimation

    def _post_set(self, params):
        """Run-time changes (covariances, time_offset; the others are read-only)."""
        apply_changes(self.cfg, PARAMETERS, params)
        self._set_covariances()

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
        # The node clock's reading (ROS time: simulated time if use_sim_time) in s, without
        # building an rclpy Time (this runs once per read of the port).
        handle = self._clock_handle
        with handle:
            return handle.get_now().nanoseconds * 1e-9

    # ------------------------------------------------------------ publishing
    def _on_batch(self, code, rec, stamps):
        """Session thread: publish one batch (stamps in integer ns)."""
        try:
            self._publish(self.serialize_batch(rec, stamps))
            self.published += len(stamps)
        except Exception:
            if self.context.ok():
                raise
            # Shutting down (signal): the last batch has nowhere to go.

    def _on_temperature(self, reading, stamp_ns):
        """Session thread: publish one temperature (deg C; variance 0 = unknown)."""
        stamp_ns += int(round(self.cfg['time_offset'] * 1e9))
        msg = Temperature()
        msg.header.frame_id = self.cfg['frame_id']
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), 10**9)
        msg.temperature = float(reading.celsius)
        msg.variance = 0.0
        try:
            self.pub_temperature.publish(msg)
        except Exception:
            if self.context.ok():
                raise

    def serialize_batch(self, rec, stamps):
        """
        Return ``[(publisher, CDR bytes of the batch's messages back to back, message size)]``.

        ``rec``: records from the session (device units), ``stamps``: int64 ns before
        ``time_offset``.  Vectorized over the batch; the bytes equal rclpy's serialization
        of each message.
        """
        offset_ns = int(round(self.cfg['time_offset'] * 1e9))
        if offset_ns:
            stamps = stamps + offset_ns
        gyro = rec['gyro']
        accel = np.multiply(rec['accel'], self.cfg['gravity'], dtype=np.float64)
        out = [(self.pub_raw, *self.pack_raw.pack(
            stamps, angular_velocity=gyro, linear_acceleration=accel))]
        if self.orientation:
            out.append((self.pub_data, *self.pack_data.pack(
                stamps, angular_velocity=gyro, linear_acceleration=accel,
                orientation=p.matrix_to_quaternion(rec['matrix']))))
        if self.has_mag:
            out.append((self.pub_mag, *self.pack_mag.pack(
                stamps, magnetic_field=np.multiply(rec['mag'], p.GAUSS_TO_TESLA,
                                                   dtype=np.float64))))
        return out

    def _publish(self, batches):
        # Per message only a slice and rclpy's raw publish of ready CDR bytes (what
        # Publisher.publish does for bytes, without its per-call type checks).
        for publisher, raw, size in batches:
            handle = publisher.handle
            with handle:
                publish = handle.publish_raw
                for start in range(0, len(raw), size):
                    publish(raw[start:start + size])

    # ------------------------------------------------------------ diagnostics
    def _diagnostics(self):
        session = self.session
        st, ps = session.stats, session.parser.stats
        now = self._now()
        then, records_then = self._diag_last
        rate = (st.records - records_then) / (now - then) if now > then else 0.0
        self._diag_last = (now, st.records)
        device_rate = p.rate_for_decimation(self.decimation)
        # The device's processing as it confirmed it with 0xDB (the requested one before that).
        sampling = session.sampling or p.SamplingSettings(self.decimation,
                                                          filter_window=self.cfg['filter_window'])
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
            'filter_window_taps': sampling.filter_window,
            'filter_window_s': sampling.filter_window / p.BASE_RATE_HZ,
            'decimation': sampling.decimation, 'internal_rate_hz': p.BASE_RATE_HZ,
            'packets': st.records, 'published': self.published,
            'checksum_failures': ps.bad_checksums, 'resyncs': ps.resyncs,
            'rejected_bytes': ps.rejected_bytes, 'dropped_packets': st.dropped,
            'stalls': st.stalls, 'reconnects': st.reconnects,
            'setup_failures': st.setup_failures, 'timer_rollovers': st.rollovers,
            'timer_resets': st.timer_resets, 'time_jumps': session.sync.jumps,
            'device_model': session.model, 'device_serial': session.serial_number,
            'firmware': session.firmware, 'state': state,
            'temperature_c': float(session.last_temperature_c),
            'temperature_readings': st.temperatures,
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


def main(args=None):
    """Entry point of ``driver``."""
    node_main('driver', DESCRIPTION, PARAMETERS, DriverNode, args)


if __name__ == '__main__':
    sys.exit(main())
