"""Axis names, term keys and unit conversions (core/units.py), against the anchors' values."""

from imu_allan.core.units import (
    ALL_TERMS,
    AXES,
    conventional,
    discrete_random_walk_step,
    discrete_white_std,
    IEEE_TERMS,
    si_unit,
    TERM_PARAMETERS,
)
import pytest


def test_unit_conversions():
    # anchors 10.1: 1 deg/sqrt(h) = 2.9089e-4 rad/sqrt(s); 1 deg/h = 4.8481e-6 rad/s;
    # 1 m/s/sqrt(h) = 1/60 m/s^2/sqrt(Hz)
    assert conventional('gyro_x', 'white_noise', 2.9089e-4)[0] == pytest.approx(1.0, rel=1e-4)
    assert conventional('gyro_y', 'bias_instability', 4.8481e-6)[0] == pytest.approx(1.0,
                                                                                     rel=1e-4)
    assert conventional('accel_x', 'white_noise', 1 / 60) == pytest.approx((1.0,
                                                                           'm/s/sqrt(h)'))
    assert conventional('gyro_z', 'rate_random_walk', 8.0802e-8)[0] == pytest.approx(1.0,
                                                                                     rel=1e-4)


def test_si_units_per_sensor_and_continuous_time():
    """Every term has an SI unit for gyro and accel axes; N and K carry sqrt(Hz)."""
    for term in ALL_TERMS:
        for axis in AXES:
            assert si_unit(axis, term)
    assert si_unit('gyro_x', 'white_noise') == 'rad/s/sqrt(Hz)'
    assert si_unit('accel_z', 'rate_random_walk') == 'm/s^3/sqrt(Hz)'
    assert set(TERM_PARAMETERS) == set(ALL_TERMS) and ALL_TERMS[:5] == IEEE_TERMS


def test_per_sample_conversions():
    """Kalibr's discretisation: sigma_d = N sqrt(f), bias step = K / sqrt(f)."""
    assert discrete_white_std(1e-3, 100.0) == pytest.approx(1e-2)
    assert discrete_random_walk_step(1e-4, 100.0) == pytest.approx(1e-5)
