"""
Axis names, noise-term keys and unit conversions shared by the whole package.

Everything inside the package is SI: rad/s and m/s^2 for samples, continuous-time noise
coefficients in the IEEE Std 952 / 1293 units of the term registry
(:data:`imu_allan.core.terms.TERMS`), which also holds each term's conventional units
(deg/sqrt(h), deg/h, m/s/sqrt(h), ...); the conversions are done here.
"""

import math

from .terms import DEG, HOUR, STANDARD_GRAVITY, TERMS  # noqa: F401 - re-exported
from ..errors import InputError

#: Axis order everywhere (topics, arrays, JSON, CSV).
AXES = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')
GYRO_AXES = AXES[:3]

#: The five IEEE terms carried on ``imu/allan_coeffs`` (in this order).
IEEE_TERMS = ('quantization', 'white_noise', 'bias_instability', 'rate_random_walk', 'rate_ramp')
#: Every term the core can model, fit and simulate (the registry's order).
ALL_TERMS = tuple(TERMS)
assert ALL_TERMS[:len(IEEE_TERMS)] == IEEE_TERMS

#: Noise-term parameter names (single-parameter terms use ``value``), from the registry.
TERM_PARAMETERS = {name: spec.params for name, spec in TERMS.items()}


def check_terms(names, where):
    """Raise InputError naming ``where`` when a name in ``names`` is not a known term."""
    unknown = [t for t in names if t not in TERMS]
    if unknown:
        raise InputError(where, f'unknown term(s) {", ".join(repr(t) for t in unknown)} '
                                f'(known: {", ".join(ALL_TERMS)})')


def parse_terms(text, where):
    """Parse a comma-separated term list: None when empty (automatic), else the names."""
    names = [t.strip() for t in str(text).split(',') if t.strip()]
    check_terms(names, where)
    return names or None


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


def si_unit(axis, term):
    """SI unit string of a term's main parameter for an axis (continuous time)."""
    return TERMS[term].si_units[sensor_of(axis)]


def conventional(axis, term, value):
    """Convert a term's SI value to conventional units; return ``(value, unit)``."""
    unit, factor = TERMS[term].conventional[sensor_of(axis)]
    return value * factor, unit


def sample_unit(axis):
    """SI unit of a sample of this axis."""
    return 'rad/s' if is_gyro(axis) else 'm/s^2'


def discrete_white_std(noise_density, rate_hz):
    """Per-sample std of white noise of continuous density N at a sample rate (Kalibr)."""
    return noise_density * math.sqrt(rate_hz)


def discrete_random_walk_step(random_walk, rate_hz):
    """Per-sample bias step std of a random walk of continuous strength K (Kalibr)."""
    return random_walk / math.sqrt(rate_hz)
