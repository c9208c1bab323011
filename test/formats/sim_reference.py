"""
The simulators' own IMU noise, re-implemented from their source for the tests.

Independent of :mod:`imu_allan.formats.gazebo_sdf`: the SDF is read here with a few lines of
ElementTree and the noise applied exactly as the C++ does, vectorised.

* gz-sensors ``GaussianNoiseModel::ApplyImpl`` (gazebosim/gz-sensors, src/GaussianNoiseModel.cc
  :111-154, commit 9ba02f2): white ``DblNormal(mean, stddev)``; the bias, when
  dynamic_bias_stddev and dynamic_bias_correlation_time > 0 and dt > 0, updated first as
  ``bias = phi_d bias + DblNormal(0, sigma_b_d)`` with ``sigma_b_d = sqrt(-sigma_b^2 tau / 2
  expm1(-2 dt / tau))``, ``phi_d = exp(-dt / tau)``; output ``in + bias + white`` rounded with
  ``std::round(out / precision) * precision`` when precision is not within 1e-6 of 0.  The bias
  starts at the turn-on draw ``DblNormal(bias_mean, bias_stddev)`` with a random sign (Load,
  :85-99).  ``ImuSensor::Update`` (src/ImuSensor.cc:218-229) passes dt as a float duration, 0 on
  the first update.
* PX4 SITL ``GazeboImuPlugin::addNoise`` (PX4/PX4-SITL_gazebo-classic,
  src/gazebo_imu_plugin.cpp:187-237, commit 807b67b): per sensor ``sigma_d = N / sqrt(dt)``,
  ``sigma_b_d = sqrt(-sigma_b^2 tau / 2 (exp(-2 dt / tau) - 1))``, ``phi_d = exp(-dt / tau)``;
  the bias (started at TurnOnBiasSigma x N(0, 1), :173-180) updated before it is added, every
  sample.
"""

import math
from xml.etree import ElementTree

import numpy as np
from scipy.signal import lfilter

GZ_PATHS = {'gyro_x': 'angular_velocity/x', 'gyro_y': 'angular_velocity/y',
            'gyro_z': 'angular_velocity/z', 'accel_x': 'linear_acceleration/x',
            'accel_y': 'linear_acceleration/y', 'accel_z': 'linear_acceleration/z'}
PX4_SENSORS = {'gyro': 'gyroscope', 'accel': 'accelerometer'}
#: Two gyro axes: white noise and a short Gauss-Markov bias, 100 Hz (hidden-effect tests).
EXAMPLE_SDF = """<sensor name="imu_sensor" type="imu">
  <update_rate>100</update_rate>
  <imu>
    <angular_velocity>
      <x>
        <noise type="gaussian">
          <stddev>0.01</stddev>
          <dynamic_bias_stddev>2e-3</dynamic_bias_stddev>
          <dynamic_bias_correlation_time>0.5</dynamic_bias_correlation_time>
        </noise>
      </x>
      <y>
        <noise type="gaussian">
          <stddev>0.01</stddev>
          <dynamic_bias_stddev>2e-3</dynamic_bias_stddev>
          <dynamic_bias_correlation_time>0.5</dynamic_bias_correlation_time>
        </noise>
      </y>
    </angular_velocity>
  </imu>
</sensor>
"""


def _gauss_markov(rng, n, drive, tau, dt, bias0, first_step):
    """b_k = phi b_(k-1) + N(0, sigma_b_d^2) from b = bias0; ``first_step``: update at k = 0."""
    sigma_b_d = math.sqrt(-drive * drive * tau / 2.0 * math.expm1(-2.0 * dt / tau))
    phi = math.exp(-dt / tau)
    w = sigma_b_d * rng.standard_normal(n)
    if not first_step:
        w[0] = 0.0
        decay = phi ** np.maximum(np.arange(n), 0)
    else:
        decay = phi ** np.arange(1, n + 1)
    return lfilter([1.0], [1.0, -phi], w) + bias0 * decay


def _first(path_or_text, tag):
    """Return the first ``tag`` element of an XML text or file (the root itself if it is one)."""
    text = path_or_text
    if not str(text).lstrip().startswith('<'):
        with open(text, encoding='utf-8') as stream:
            text = stream.read()
    return next(ElementTree.fromstring(text).iter(tag))


def gz_noise_params(path_or_text):
    """{axis: {field: float}} of the first <imu> element (fields gz-sensors reads)."""
    imu = _first(path_or_text, 'imu')
    out = {}
    for axis, path in GZ_PATHS.items():
        noise = imu.find(f'{path}/noise')
        if noise is None:
            continue
        out[axis] = {name: float(noise.findtext(name, '0')) for name in (
            'mean', 'stddev', 'bias_mean', 'bias_stddev', 'dynamic_bias_stddev',
            'dynamic_bias_correlation_time', 'precision')}
    return out


def gz_apply(p, n, rate_hz, rng, signal=0.0):
    """gz-sensors' Gaussian noise on ``n`` samples of one axis (module docstring)."""
    dt = float(np.float32(1.0 / rate_hz))
    white = rng.normal(p['mean'], p['stddev'], n) if p['stddev'] > 0 else p['mean']
    bias0 = rng.normal(p['bias_mean'], p['bias_stddev']) if p['bias_stddev'] > 0 \
        else p['bias_mean']
    if rng.uniform() < 0.5:
        bias0 = -bias0
    drive, tau = p['dynamic_bias_stddev'], p['dynamic_bias_correlation_time']
    bias = _gauss_markov(rng, n, drive, tau, dt, bias0, False) if drive > 0 and tau > 0 \
        else bias0
    out = signal + bias + white
    prec = p['precision']
    if abs(prec) > 1e-6:
        v = out / prec
        out = np.sign(v) * np.floor(np.abs(v) + 0.5) * prec  # std::round: half away from 0
    return np.asarray(out, dtype=float) * np.ones(n)


def gz_simulate(params, axes, n, rate_hz, seed):
    """(n, len(axes)) samples of the axes from :func:`gz_noise_params` output."""
    rng = np.random.default_rng(seed)
    return np.column_stack([gz_apply(params[a], n, rate_hz, rng) for a in axes])


def px4_params(path_or_text):
    """{key: float} of the gazebo_imu_plugin block (keys present only)."""
    plugin = _first(path_or_text, 'plugin')
    return {c.tag: float(c.text) for c in plugin
            if isinstance(c.tag, str) and c.tag.startswith(('gyroscope', 'accelerometer'))}


def px4_simulate(params, axes, n, rate_hz, seed):
    """PX4 plugin noise on ``n`` samples of the axes (all keys must be given)."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    cols = []
    for axis in axes:
        prefix = PX4_SENSORS['gyro' if axis.startswith('gyro') else 'accel']
        density = params[f'{prefix}NoiseDensity']
        drive = params[f'{prefix}RandomWalk']
        tau = params[f'{prefix}BiasCorrelationTime']
        bias0 = params[f'{prefix}TurnOnBiasSigma'] * rng.standard_normal()
        bias = _gauss_markov(rng, n, drive, tau, dt, bias0, True)
        cols.append(bias + density / math.sqrt(dt) * rng.standard_normal(n))
    return np.column_stack(cols)
