"""imu_allan: IMU noise monitoring with the Allan variance (ROS 2 Jazzy package).

The ROS-free Python API (SI units, continuous-time coefficients)::

    import imu_allan
    result = imu_allan.allan_deviation(data, rate_hz)      # (n, A) -> tau, adev, ci_low/high
    model = imu_allan.fit_noise_model(result)              # terms with 68.3 % intervals
    sim = imu_allan.simulate(model.model, n, rate_hz, seed=1)

Names are loaded on first use (PEP 562) so that commands answering ``--help`` or rejecting bad
input do not pay for importing scipy.
"""

import importlib
import os

# The fits solve many small (< 100 x 100) systems: BLAS threads only add overhead there, and on
# a 2-core robot computer they were measured to make them 15x slower.  A default, not a rule.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

_API = {
    'allan_deviation': 'core.allan', 'AllanResult': 'core.allan',
    'fit_noise_model': 'core.fit', 'FittedModel': 'core.fit',
    'NoiseModel': 'core.model', 'thesis_gx3_25_model': 'core.model',
    'simulate': 'core.simulate',
    'AXES': 'core.units', 'IEEE_TERMS': 'core.units',
}
__all__ = sorted(_API)


def __getattr__(name):
    """Import the module that defines ``name`` on first access."""
    if name not in _API:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'.{_API[name]}', __name__), name)
    globals()[name] = value
    return value


def __dir__():
    """List the public API."""
    return sorted(list(globals()) + __all__)
