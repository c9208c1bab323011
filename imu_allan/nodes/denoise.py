"""
denoise: wavelet (or median) denoising of imu/data_raw, republished as imu/data_denoised.

Subscribes ``imu/data_raw`` (sensor-data QoS, deep queue, taken in batches by a timer) and
publishes ``imu/data_denoised`` (sensor_msgs/Imu): the same messages (header stamps, frame,
orientation, covariances untouched) with denoised angular velocity and linear acceleration,
``latency_s`` later at most (``--help`` and docs/online.md give the latency of each setting).

The numerics are :class:`imu_allan.core.denoise.BlockDenoiser`: overlapping blocks, each
denoised by the batch :func:`imu_allan.core.denoise.denoise`.  With ``noise_source: allan`` the
per-sample white-noise level comes from the white-noise coefficients on ``imu/allan_coeffs``
(sigma = N sqrt(rate)); then the output equals the batch denoiser of the whole record with that
noise level.  With ``mad`` each block estimates its own noise level per wavelet level.
"""

from collections import deque

import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray

from .common import (
    apply_changes,
    declare_parameter_table,
    node_main,
    Param,
    polled_subscription,
    sensor_publisher,
    take_batch,
    validate_on_set,
)
from ..core.live.health import RateFinder
from ..core.units import AXES, IEEE_TERMS
from ..errors import InputError
from ..formats.imu_adapter import imus_to_arrays
from ..report.coeffs_layout import ADEQUACY_VALUES, decode_table

DESCRIPTION = ('Wavelet (PyWavelets) or median denoising of imu/data_raw on overlapping blocks '
               'with bounded latency; publishes imu/data_denoised with the original stamps.')

#: The parameter table (nodes.common.Param).
PARAMETERS = [
    Param('rate_hz', 0.0, 'sample rate of imu/data_raw, Hz (block sizes, noise conversion); '
                          '0 = measured from the header stamps (median spacing, first 2 s)',
          (0.0, 10000.0)),
    Param('method', 'wavelet', 'wavelet or median'),
    Param('wavelet', 'sym8', 'PyWavelets discrete wavelet (sym8 as in the thesis; haar, db4, '
                             '...)'),
    Param('level', 4, 'decomposition levels; latency about (filter length - 1) x 2^level samples '
                      '(sym8: 240 samples at level 4, 61440 at level 12)', (1, 20)),
    Param('rule', 'universal', 'threshold rule: universal, minimax or sure'),
    Param('mode', 'soft', 'soft or hard thresholding'),
    Param('noise_source', 'mad', 'mad (per block and level) or allan (white-noise coefficient '
                                 'from imu/allan_coeffs)'),
    Param('median_window', 21, 'median filter window, samples', (1, 100001)),
    Param('hop_s', 0.1, 'output step, s (rounded up to 2^level samples)', (0.0001, 60.0)),
    Param('drain_period', 0.02, 'seconds between taking the queued messages (read-only)',
          (0.001, 1.0), read_only=True),
    Param('queue_depth', 5000, 'subscription queue depth (read-only)',
          (10, 1000000), read_only=True),
]
_DEFAULTS = {p.name: p.default for p in PARAMETERS}
_DENOISER = {'rate_hz', 'method', 'wavelet', 'level', 'rule', 'mode', 'median_window', 'hop_s',
             'noise_source'}


def check_parameters(p):
    """Validate a full parameter dictionary; raise InputError with the reason."""
    from ..core.denoise import check_options
    try:
        check_options(p['method'], p['wavelet'], p['level'], p['rule'], p['mode'],
                      p['median_window'])
    except ValueError as exc:
        text = str(exc)
        where = next((k for k in ('median_window', 'method', 'wavelet', 'level', 'rule', 'mode')
                      if k in text), 'parameters')
        raise InputError(where, text) from None
    if p['noise_source'] not in ('mad', 'allan'):
        raise InputError('noise_source', 'must be mad or allan')


def make_denoiser(p):
    """Return a :class:`BlockDenoiser` for six axes from a parameter dictionary."""
    from ..core.denoise import BlockDenoiser
    return BlockDenoiser(p['rate_hz'], len(AXES), hop_s=p['hop_s'], method=p['method'],
                         wavelet=p['wavelet'], level=p['level'], rule=p['rule'],
                         mode=p['mode'], median_window=p['median_window'])


def white_noise_from_coeffs(data, dims):
    """
    White-noise coefficient N per axis (6,) from an ``imu/allan_coeffs`` payload, or None.

    ``dims`` is the layout as ``(label, size)`` pairs.
    """
    if tuple(size for _, size in dims) != (len(AXES), len(IEEE_TERMS), 3):
        return None
    table = decode_table(data, dims, ADEQUACY_VALUES)  # (the adequacy block follows)
    n = table[:, IEEE_TERMS.index('white_noise'), 0]
    return n if np.all(np.isfinite(n)) and np.all(n > 0) else None


def main(args=None):
    """Entry point ``denoise``."""
    node_main('denoise', DESCRIPTION, PARAMETERS, DenoiseNode, args)


class DenoiseNode(Node):
    def __init__(self):
        super().__init__('denoise')
        self.params = declare_parameter_table(self, PARAMETERS)
        check_parameters(self.params)
        self._new_denoiser()
        self._pending = deque()  # messages waiting for their denoised values
        self._noise = None
        self.add_on_set_parameters_callback(validate_on_set(self.params, PARAMETERS,
                                                            check_parameters))
        self.add_post_set_parameters_callback(self._post_set)
        depth = int(self.params['queue_depth'])
        self._sub = polled_subscription(self, Imu, 'imu/data_raw', depth)
        self._max_batch = depth
        self._pub = sensor_publisher(self, Imu, 'imu/data_denoised')
        self._coeff_sub = self.create_subscription(
            Float64MultiArray, 'imu/allan_coeffs', self._on_coeffs, 10)
        self._log_latency()
        self._timer = self.create_timer(self.params['drain_period'], self.drain)

    def _new_denoiser(self):
        """Return a denoiser for the configured rate, or a RateFinder until it is measured."""
        rate = self.params['rate_hz']
        self.finder = None if rate else RateFinder()
        self.denoiser = make_denoiser(self.params) if rate else None
        self._rate = rate

    def _log_latency(self):
        d = self.denoiser
        if d is None:
            self.get_logger().info(f'{self.params["method"]} denoising once the sample rate '
                                   f'is measured from the stamps')
            return
        self.get_logger().info(
            f'{self.params["method"]} denoising, latency up to {d.latency_samples} samples '
            f'({d.latency_s:.3g} s at {self._rate:.6g} Hz'
            f'{"" if self.finder is None else ", measured"})')

    def _post_set(self, params):
        changed = apply_changes(self.params, PARAMETERS, params)
        if changed & _DENOISER:
            # Finish the samples in flight with the old settings, then switch.
            if self.denoiser is not None:
                self._publish_rows(self.denoiser.flush())
            held = self.finder.take() if self.finder is not None and self.finder.n_held else None
            self._new_denoiser()
            self._apply_noise()
            self._log_latency()
            if held is not None:  # samples held for a rate measurement are not lost
                self._feed(*held)

    def _on_coeffs(self, msg):
        dims = [(d.label, d.size) for d in msg.layout.dim]
        self._noise = white_noise_from_coeffs(msg.data, dims)
        self._apply_noise()

    def _apply_noise(self):
        if self.denoiser is None:
            return
        if self.params['noise_source'] == 'allan' and self._noise is not None:
            self.denoiser.set_noise(noise_density=self._noise)
        else:
            self.denoiser.set_noise()

    def drain(self):
        """Take the queued messages, denoise, publish what is ready."""
        msgs = take_batch(self._sub, self._max_batch)
        if not msgs:
            return
        t, data = imus_to_arrays(msgs)
        self._pending.extend(msgs)
        self._feed(t, data)

    def _feed(self, t, data):
        if self.denoiser is None:  # measuring the rate: hold the samples until it is known
            if self.finder.add(t, data) is None:
                return
            self._rate = self.finder.rate_hz
            self.denoiser = make_denoiser(dict(self.params, rate_hz=self._rate))
            self._apply_noise()
            self._log_latency()
            t, data = self.finder.take()
        self._publish_rows(self.denoiser.push(data))

    def _publish_rows(self, rows):
        for row in rows:
            msg = self._pending.popleft()
            w, a = msg.angular_velocity, msg.linear_acceleration
            w.x, w.y, w.z, a.x, a.y, a.z = (float(v) for v in row)
            self._pub.publish(msg)
