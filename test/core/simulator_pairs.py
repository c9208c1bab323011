"""
IMU simulators' noise, intended and as implemented, re-implemented here from their sources.

Written for the discrepancy findings tests, independently of the package (no
``imu_allan.core.simulation.simulate``, no ``imu_allan.formats.gazebo_sdf``): each *pair* is the
noise a simulator's parameters are documented (or reported) to mean, and the noise its code
produces, vectorised from the C++ with the same recursions.  Sources, as read (public
repositories):

* gz-sensors ``src/GaussianNoiseModel.cc`` (gazebosim/gz-sensors, 9ba02f2, the version with
  ``ApplyImpl(double _in, double _dt)``): ``Load`` draws the constant bias
  ``DblNormal(bias_mean, bias_stddev)`` and flips its sign with probability 1/2 (gz-sensors#360);
  ``ApplyImpl`` adds ``DblNormal(mean, stddev)`` per sample (not scaled by dt: gazebo-classic
  #2670) and, when ``dynamic_bias_stddev`` and ``dynamic_bias_correlation_time`` and dt are
  positive, first updates that same bias as ``bias = phi_d bias + DblNormal(0, sigma_b_d)`` with
  ``sigma_b_d = sqrt(-sigma_b^2 tau / 2 expm1(-2 dt / tau))`` (the stationary std is then
  sigma_b sqrt(tau / 2), gz-sensors#616), so the turn-on bias is the process's start and decays.
  Before that version (b394cc6, ``ApplyImpl(double _in)``) the dynamic bias was not applied.
  ``src/ImuSensor.cc`` (3ead9f2) passes dt as a float duration, 0 on the first update.
* PX4-SITL_gazebo-classic ``src/gazebo_imu_plugin.cpp`` (03fa8f2): ``Load`` fills the Imu
  message's covariance diagonals with NoiseDensity^2 (a density, not the per-sample variance
  NoiseDensity^2 / dt) and draws the turn-on bias ``TurnOnBiasSigma N(0, 1)`` per axis;
  ``addNoise`` adds per sample ``NoiseDensity / sqrt(dt) N(0, 1)`` and a Gauss-Markov bias
  ``b = phi_d b + sigma_b_d N(0, 1)``, ``sigma_b_d = sqrt(-RandomWalk^2 tau / 2 (exp(-2 dt / tau)
  - 1))`` (RandomWalk is the driving density), started at 0.  Defaults of the iris model:
  gyro 0.00018665 / 3.8785e-5 / 1000 s / 0.0087, accel 0.00186 / 0.006 / 300 s / 0.196.
* tu-darmstadt-ros-pkg/hector_gazebo ``hector_gazebo_plugins/include/hector_gazebo_plugins/
  sensor_model.h`` (1ae0ea0): ``current_drift = current_drift - dt * (current_drift *
  drift_frequency + N(0, sqrt(2 drift_frequency) drift))``: the drive is stepped with dt where
  a Gauss-Markov of stationary std ``drift`` needs sqrt(dt); ``gaussianNoise`` is per sample.

The gz sample configuration is the one the Gazebo sensor-noise tutorial and many robot models
carry: gyro stddev 0.009, bias_mean 0.00075, bias_stddev 0.005, dynamic_bias_stddev 2e-5 over
400 s; accel stddev 0.021, bias_mean 0.05, bias_stddev 0.0075, dynamic 3.5e-5 over 300 s.

Every function returns samples (n, len(axes)) in SI units and, where it matters, the truth the
findings should report.
"""

import math

import numpy as np
from scipy.signal import lfilter

GZ_TUTORIAL = {
    'gyro': {'stddev': 0.009, 'bias_mean': 0.00075, 'bias_stddev': 0.005,
             'dynamic_bias_stddev': 2e-5, 'dynamic_bias_correlation_time': 400.0},
    'accel': {'stddev': 0.021, 'bias_mean': 0.05, 'bias_stddev': 0.0075,
              'dynamic_bias_stddev': 3.5e-5, 'dynamic_bias_correlation_time': 300.0},
}
PX4_IRIS = {
    'gyro': {'density': 0.00018665, 'random_walk': 3.8785e-5, 'tau': 1000.0, 'turn_on': 0.0087},
    'accel': {'density': 0.00186, 'random_walk': 0.006, 'tau': 300.0, 'turn_on': 0.196},
}


def sensor(axis):
    """'gyro' or 'accel'."""
    return 'gyro' if axis.startswith('gyro') else 'accel'


def ar1(rng, n, phi, step_sd, x0=0.0, mean_step=0.0, uniform=False):
    """
    x_k = phi x_(k-1) + mean_step + step_sd N(0, 1), k = 0..n-1, from x_(-1) = x0.

    ``uniform`` True draws U[0, 1) where N(0, 1) is meant (a ``rand() / RAND_MAX`` in place of
    the normal generator): the drive then has a mean of 0.5 and a std of 1 / sqrt(12) = 0.289
    step_sd.
    """
    w = mean_step + step_sd * (rng.random(n) if uniform else rng.standard_normal(n))
    zi = np.array([phi * x0])
    return lfilter([1.0], [1.0, -phi], w, zi=zi)[0]


# ---------------------------------------------------------------- gz-sensors


def gz_axis(rng, n, rate_hz, p, per_sample=True, driving=True, dynamic=True, random_sign=True,
            turn_on_in_process=True, uniform_drive=False):
    """
    One axis of gz-sensors' GaussianNoiseModel (``per_sample`` etc. True: the code as it is).

    ``per_sample`` False scales stddev by 1/sqrt(dt) (stddev read as a density);
    ``driving`` False uses sigma_b_d = sigma_b sqrt(-expm1(-2 dt / tau)) (dynamic_bias_stddev
    read as the stationary std, gz-sensors#616); ``dynamic`` False ignores the dynamic bias (the
    version before it); ``random_sign`` False keeps the turn-on bias's sign;
    ``turn_on_in_process`` False keeps the turn-on bias constant beside the process;
    ``uniform_drive`` True draws the dynamic bias's drive from U[0, 1) (:func:`ar1`).
    """
    dt = float(np.float32(1.0 / rate_hz))  # ImuSensor::Update: a float duration
    bias0 = rng.normal(p.get('bias_mean', 0.0), p.get('bias_stddev', 0.0)) \
        if p.get('bias_stddev', 0.0) > 0 else p.get('bias_mean', 0.0)
    if rng.uniform() < 0.5 and random_sign:
        bias0 = -bias0
    white_sd = p.get('stddev', 0.0) * (1.0 if per_sample else 1.0 / math.sqrt(dt))
    white = white_sd * rng.standard_normal(n)
    drive, tau = p.get('dynamic_bias_stddev', 0.0), p.get('dynamic_bias_correlation_time', 0.0)
    if not (dynamic and drive > 0 and tau > 0):
        return bias0 + white
    sigma_b_d = math.sqrt(-drive * drive * tau / 2.0 * math.expm1(-2.0 * dt / tau)) \
        if driving else drive * math.sqrt(-math.expm1(-2.0 * dt / tau))
    phi = math.exp(-dt / tau)
    start = bias0 if turn_on_in_process else 0.0
    bias = ar1(rng, n, phi, sigma_b_d, x0=start, uniform=uniform_drive)
    bias[0] = start  # the first update has dt = 0: no bias step
    return bias + (0.0 if turn_on_in_process else bias0) + white


def gz_run(axes, n, rate_hz, seed, config=GZ_TUTORIAL, **code):
    """(n, len(axes)) samples of gz-sensors with ``config`` per sensor (``code``: gz_axis)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([gz_axis(rng, n, rate_hz, config[sensor(a)], **code) for a in axes])


# ---------------------------------------------------------------- PX4 SITL (gazebo classic)


def px4_axis(rng, n, rate_hz, p, walk=False, turn_on=True, tau=None, drive_mean=0.0,
             uniform_drive=False):
    """
    One axis of gazebo_imu_plugin's addNoise (defaults: the code as it is).

    ``walk`` True drops the decay (phi = 1, the step sd of tau -> inf: an unbounded random
    walk of strength RandomWalk); ``turn_on`` False draws no turn-on bias; ``tau`` replaces the
    correlation time; ``drive_mean`` adds a mean to the bias drive per step (units of its sd);
    ``uniform_drive`` draws the bias drive from U[0, 1) (:func:`ar1`).
    """
    dt = 1.0 / rate_hz
    tau = p['tau'] if tau is None else tau
    b_on = p['turn_on'] * rng.standard_normal() if turn_on else 0.0
    rw = p['random_walk']
    if walk:
        phi, step = 1.0, rw * math.sqrt(dt)
    else:
        phi = math.exp(-dt / tau)
        step = math.sqrt(-rw * rw * tau / 2.0 * (math.exp(-2.0 * dt / tau) - 1.0))
    bias = ar1(rng, n, phi, step, mean_step=drive_mean * step, uniform=uniform_drive)
    return bias + p['density'] / math.sqrt(dt) * rng.standard_normal(n) + b_on


def px4_run(axes, n, rate_hz, seed, config=PX4_IRIS, tau_of=None, **code):
    """(n, len(axes)) samples of the PX4 plugin; ``tau_of`` = {sensor: tau} overrides."""
    rng = np.random.default_rng(seed)
    cols = []
    for a in axes:
        p = config[sensor(a)]
        tau = (tau_of or {}).get(sensor(a))
        cols.append(px4_axis(rng, n, rate_hz, p, tau=tau, **code))
    return np.column_stack(cols)


def px4_covariance(axes, rate_hz, config=PX4_IRIS, per_sample=False):
    """Return the covariance diagonal the plugin publishes: density^2 (``per_sample``: / dt)."""
    return {a: config[sensor(a)]['density'] ** 2 * (rate_hz if per_sample else 1.0)
            for a in axes}


# ---------------------------------------------------------------- hector_gazebo


def hector_axis(rng, n, rate_hz, drift, drift_frequency, white_density, sqrt_dt=False):
    """
    Run hector's SensorModelInternalUpdate on one axis (``sqrt_dt`` True: the intended step).

    current_drift -= dt (current_drift f + N(0, sqrt(2 f) drift)) as the code does; with
    ``sqrt_dt`` the drive is stepped with sqrt(dt), a Gauss-Markov of stationary std ``drift``
    and correlation time 1 / f.  The white part is given as a density here (gaussianNoise set
    to white_density sqrt(rate) for each rate) so that the pair differs in the drift only.
    """
    dt = 1.0 / rate_hz
    phi = 1.0 - dt * drift_frequency
    kernel = math.sqrt(2.0 * drift_frequency) * drift
    step = kernel * (math.sqrt(dt) if sqrt_dt else dt)
    x0 = drift * rng.standard_normal() if sqrt_dt else 0.0
    current = ar1(rng, n, phi, step, x0=x0)
    return current + white_density * math.sqrt(rate_hz) * rng.standard_normal(n)
