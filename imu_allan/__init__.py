"""imu_allan: IMU noise monitoring with the Allan variance (ROS 2 Jazzy package).

The ROS-free Python API (SI units, continuous-time coefficients)::

    import imu_allan
    result = imu_allan.allan_deviation(data, rate_hz)      # (n, A) -> tau, adev, ci_low/high
    model = imu_allan.fit_noise_model(result)              # terms with 68.3 % intervals
    sim = imu_allan.simulate(model.model, n, rate_hz, seed=1)
"""

from .core.allan import AllanResult, allan_deviation
from .core.fit import FittedModel, fit_noise_model
from .core.model import NoiseModel, thesis_gx3_25_model
from .core.simulate import simulate
from .core.units import AXES, IEEE_TERMS

__all__ = ['allan_deviation', 'AllanResult', 'fit_noise_model', 'FittedModel', 'NoiseModel',
           'thesis_gx3_25_model', 'simulate', 'AXES', 'IEEE_TERMS']
