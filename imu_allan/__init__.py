"""
imu_allan: IMU noise monitoring with the Allan variance (ROS 2 Jazzy package).

The ROS-free Python API (SI units, continuous-time coefficients)::

    import imu_allan
    result = imu_allan.allan_deviation(data, rate_hz)      # (n, A) -> tau, adev, ci_low/high
    model = imu_allan.fit_noise_model(result)              # terms with 68.3 % intervals
    sim = imu_allan.simulate(model.model, n, rate_hz, seed=1)
    samples = imu_allan.read_samples('my_bag/')            # any supported recording

Names are loaded on first use (PEP 562) so that commands answering ``--help`` or rejecting bad
input do not pay for importing scipy.  Importing the package changes nothing in the process
environment (the commands and nodes set their BLAS threading themselves).
"""

import importlib

__version__ = '0.1.0'

_API = {
    # Allan deviation, EDF and intervals
    'allan_deviation': 'core.allan.estimate', 'AllanResult': 'core.allan.estimate',
    'edf_oadev': 'core.allan.edf', 'chi2_interval': 'core.allan.edf', 'CI_LEVEL': 'core.allan.edf',
    # the family of deviations (Stable32's), with intervals
    'deviation': 'core.deviations', 'DeviationResult': 'core.deviations',
    # noise terms, fit, models, simulation
    'fit_noise_model': 'core.fit', 'FittedModel': 'core.fit',
    'NoiseModel': 'core.model', 'thesis_gx3_25_model': 'core.model',
    'simulate': 'core.simulation.simulate',
    'export': 'report.exporters',
    # streaming and online estimation
    'StreamingAllan': 'core.live.streaming', 'OnlineAllan': 'core.live.online',
    'online_allan': 'core.live.online',
    # denoising, discrepancy workflow
    'denoise': 'core.denoise', 'run_discrepancy': 'core.discrepancy',
    # recordings
    'read_samples': 'formats.readers', 'Samples': 'formats.samples',
    # names and units
    'AXES': 'core.units', 'IEEE_TERMS': 'core.units', 'InputError': 'errors',
}
__all__ = sorted(_API) + ['__version__']


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
