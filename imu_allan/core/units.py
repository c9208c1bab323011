"""Axis names, noise-term keys and unit conversions shared by the whole package.

Everything inside the package is SI: rad/s and m/s^2 for samples, continuous-time noise
coefficients in the IEEE Std 952 / 1293 units listed in :data:`TERM_UNITS`.  Conversions to the
conventional units engineers read on datasheets (deg/sqrt(h), deg/h, m/s/sqrt(h), ...) live here
and only here.
"""

import math

#: Axis order everywhere (topics, arrays, JSON, CSV).
AXES = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')
GYRO_AXES = AXES[:3]
ACCEL_AXES = AXES[3:]

#: The five IEEE terms carried on ``imu/allan_coeffs`` (in this order).
IEEE_TERMS = ('quantization', 'white_noise', 'bias_instability', 'rate_random_walk', 'rate_ramp')
#: Every term the core can model, fit and simulate.
ALL_TERMS = IEEE_TERMS + ('gauss_markov', 'sinusoid')

#: Standard gravity, m/s^2 (used for g -> m/s^2 unless the input states a local value).
STANDARD_GRAVITY = 9.80665
DEG = math.pi / 180.0
HOUR = 3600.0

#: Noise-term parameter names (single-parameter terms use ``value``).
TERM_PARAMETERS = {
    'quantization': ('value',),
    'white_noise': ('value',),
    'bias_instability': ('value',),
    'rate_random_walk': ('value',),
    'rate_ramp': ('value',),
    'gauss_markov': ('sigma', 'tau_c'),
    'sinusoid': ('amplitude', 'frequency_hz'),
}


#: Largest magnitude a sample of a real IMU can have, SI (rad/s, m/s^2): far beyond the full
#: scale of any MEMS or tactical gyro (+-2000 deg/s = 35 rad/s is typical, a few reach 175
#: rad/s) and accelerometer (+-200 g = 2000 m/s^2 for shock-rated parts).  A value beyond it is
#: damage or a unit error, not a measurement; every intake (offline and live) checks it here.
PHYSICAL_LIMIT = {'gyro': 1.0e3, 'accel': 1.0e4}


def physical_limits(axes):
    """Per-axis physical limits (SI) as a list, in the order of ``axes``."""
    return [PHYSICAL_LIMIT[sensor_of(a)] for a in axes]


def is_gyro(axis):
    """Return True for a gyroscope axis name."""
    return axis.startswith('gyro')


def sensor_of(axis):
    """Return ``'gyro'`` or ``'accel'`` for an axis name."""
    return 'gyro' if is_gyro(axis) else 'accel'


# SI units of each term's main parameter, continuous time; q is rad (gyro) or m/s (accel).
_SI_UNITS = {
    'gyro': {
        'quantization': 'rad',
        'white_noise': 'rad/s/sqrt(Hz)',
        'bias_instability': 'rad/s',
        'rate_random_walk': 'rad/s^2/sqrt(Hz)',
        'rate_ramp': 'rad/s^2',
        'gauss_markov': 'rad/s',
        'sinusoid': 'rad/s',
    },
    'accel': {
        'quantization': 'm/s',
        'white_noise': 'm/s^2/sqrt(Hz)',
        'bias_instability': 'm/s^2',
        'rate_random_walk': 'm/s^3/sqrt(Hz)',
        'rate_ramp': 'm/s^3',
        'gauss_markov': 'm/s^2',
        'sinusoid': 'm/s^2',
    },
}

# Conventional units: (label, factor) so that conventional = SI * factor.
_CONVENTIONAL = {
    'gyro': {
        'quantization': ('deg', 1.0 / DEG),
        'white_noise': ('deg/sqrt(h)', math.sqrt(HOUR) / DEG),
        'bias_instability': ('deg/h', HOUR / DEG),
        'rate_random_walk': ('deg/h/sqrt(h)', HOUR * math.sqrt(HOUR) / DEG),
        'rate_ramp': ('deg/h^2', HOUR * HOUR / DEG),
        'gauss_markov': ('deg/h', HOUR / DEG),
        'sinusoid': ('deg/s', 1.0 / DEG),
    },
    'accel': {
        'quantization': ('m/s', 1.0),
        'white_noise': ('m/s/sqrt(h)', math.sqrt(HOUR)),
        'bias_instability': ('m/s/h', HOUR),
        'rate_random_walk': ('m/s/h/sqrt(h)', HOUR * math.sqrt(HOUR)),
        'rate_ramp': ('m/s/h^2', HOUR * HOUR),
        'gauss_markov': ('m/s/h', HOUR),
        'sinusoid': ('mg', 1e3 / STANDARD_GRAVITY),
    },
}


def si_unit(axis, term):
    """SI unit string of a term's main parameter for an axis (continuous time)."""
    return _SI_UNITS[sensor_of(axis)][term]


def conventional(axis, term, value):
    """Convert a term's SI value to conventional units; return ``(value, unit)``."""
    unit, factor = _CONVENTIONAL[sensor_of(axis)][term]
    return value * factor, unit


def sample_unit(axis):
    """SI unit of a sample of this axis."""
    return 'rad/s' if is_gyro(axis) else 'm/s^2'


def g_to_mps2(values, gravity=STANDARD_GRAVITY):
    """Convert accelerations in g to m/s^2 with the given gravity (m/s^2 per g)."""
    return values * gravity


def deg_to_rad(values):
    """Convert degrees (or deg/s) to radians (or rad/s)."""
    return values * DEG


def rad_to_deg(values):
    """Convert radians (or rad/s) to degrees (or deg/s)."""
    return values / DEG


def discrete_white_std(noise_density, rate_hz):
    """Per-sample std of white noise of continuous density N at a sample rate (Kalibr)."""
    return noise_density * math.sqrt(rate_hz)


def discrete_random_walk_step(random_walk, rate_hz):
    """Per-sample bias step std of a random walk of continuous strength K (Kalibr)."""
    return random_walk / math.sqrt(rate_hz)
