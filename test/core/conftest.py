"""Fixtures shared by the core tests."""

from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
import pytest

RATE = 100.0


@pytest.fixture(scope='module')
def record():
    """40,000 samples (400 s at 100 Hz) of the thesis 3DM-GX3-25 model, gravity on accel_z."""
    data = simulate(thesis_gx3_25_model(), 40000, RATE, seed=5)
    data[:, 5] += 9.80665
    return data
