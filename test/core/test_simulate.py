"""Closed-form Allan variance of every term (anchors 10.1) and the simulator against them."""

import math

from imu_allan import allan_deviation, NoiseModel, simulate
from imu_allan.core.simulate import flicker_noise
from imu_allan.core.terms import (
    FLICKER_FLOOR,
    flicker_shape,
    gauss_markov_shape,
    model_avar,
    sinusoid_shape,
    term_avar,
)
import numpy as np
import pytest


def test_flicker_floor_constant():
    # sqrt(2 ln2 / pi), not 0.644 (thesis MATLAB slip) nor 0.798 (log2 slip, pitfall 4).
    assert FLICKER_FLOOR == pytest.approx(0.664282, abs=1e-6)


@pytest.mark.parametrize('f0_tau,ratio', [(0.1, 0.1744), (0.3, 0.4607), (1, 0.6564),
                                          (3, 0.6633), (10, 0.6642), (100, 0.6643)])
def test_exact_flicker_transient(f0_tau, ratio):
    assert math.sqrt(flicker_shape(f0_tau, 1.0)) == pytest.approx(ratio, abs=1e-4)


def test_read_off_points_of_the_ieee_terms():
    # sigma = Q at sqrt(3), N at 1, K at 3, R at sqrt(2) (IEEE 952 read-off rules).
    adev = lambda term, tau: math.sqrt(term_avar(term, {'value': 2.0}, tau, 1e9))  # noqa: E731
    assert adev('quantization', math.sqrt(3)) == pytest.approx(2.0)
    assert adev('white_noise', 1.0) == pytest.approx(2.0)
    assert adev('rate_random_walk', 3.0) == pytest.approx(2.0)
    assert adev('rate_ramp', math.sqrt(2)) == pytest.approx(2.0)


def test_gauss_markov_peak():
    # ADEV peaks at 1.8926 Tc with 0.4365 q_c sqrt(Tc); q_c^2 = 2 sigma^2 / Tc.
    tc, sigma = 7.0, 0.3
    tau = np.logspace(-1, 3, 20001)
    adev = sigma * np.sqrt(gauss_markov_shape(tau, tc))
    k = int(np.argmax(adev))
    assert tau[k] / tc == pytest.approx(1.8926, rel=1e-3)
    assert adev[k] == pytest.approx(0.4365 * math.sqrt(2 * sigma ** 2 / tc) * math.sqrt(tc),
                                    rel=1e-3)
    # the closed form and its small-tau series agree where they hand over
    assert gauss_markov_shape(0.0099 * tc, tc) == pytest.approx(
        gauss_markov_shape(0.0101 * tc, tc) * 0.0099 / 0.0101, rel=1e-3)


def test_sinusoid_peak_and_nulls():
    f0 = 0.5
    tau = np.linspace(0.05, 1.5, 100001) / f0
    adev = np.sqrt(sinusoid_shape(tau, f0))
    k = int(np.argmax(adev))
    assert tau[k] * f0 == pytest.approx(0.37101, abs=1e-4)
    assert adev[k] == pytest.approx(0.72461, abs=1e-5)
    assert sinusoid_shape(1.0 / f0, f0) == pytest.approx(0.0, abs=1e-20)


@pytest.mark.parametrize('terms', [
    {'white_noise': 1e-3},
    {'quantization': 1e-3},
    {'bias_instability': 1e-4},
    {'rate_random_walk': 1e-5},
    {'rate_ramp': 1e-6},
    {'gauss_markov': {'sigma': 1e-3, 'tau_c': 5.0}},
    {'sinusoid': {'amplitude': 1e-3, 'frequency_hz': 0.2}},
])
def test_simulated_term_matches_its_analytic_curve(terms):
    # Average of 6 seeds, 1 h at 100 Hz, tau from 0.1 s to T/10. Tolerance: each averaged
    # AVAR must sit within 3 standard errors (from the EDF of 6 pooled runs) plus 3 % for the
    # discrete-vs-continuous shape at short tau; a wrong scale (sqrt 2, 0.664) fails by far.
    model = NoiseModel({'gyro_x': terms})
    runs = [allan_deviation(simulate(model, 360_000, 100.0, seed=s), 100.0) for s in range(6)]
    tau = runs[0].tau
    mean = np.mean([r.avar[:, 0] for r in runs], axis=0)
    edf = np.sum([r.edf[:, 0] for r in runs], axis=0)
    theory = model_avar(model.terms['gyro_x'], tau, 100.0)
    use = (tau >= 0.1) & (theory > 1e-30)
    rel = np.abs(mean[use] / theory[use] - 1.0)
    limit = 3.0 * np.sqrt(2.0 / edf[use]) + 0.03
    assert np.all(rel < limit), (tau[use][rel >= limit], rel[rel >= limit])


def test_flicker_is_one_over_f_not_gauss_markov():
    # A true 1/f series has a flat ADEV over decades; one Gauss-Markov would rise then fall.
    rng = np.random.default_rng(4)
    y = np.mean([flicker_noise(rng, 200_000, 100.0, 1.0) for _ in range(4)], axis=0) * 2.0
    r = allan_deviation(y, 100.0, taus=[0.1, 1.0, 10.0, 100.0])
    assert np.all(np.abs(r.adev[:, 0] / FLICKER_FLOOR - 1.0) < 0.12)


def test_simulate_is_seeded_and_shaped():
    model = NoiseModel.from_dict({'gyro': {'white_noise': 1e-3}, 'accel': {'white_noise': 1e-2}})
    a = simulate(model, 1000, 100.0, seed=42)
    b = simulate(model, 1000, 100.0, seed=42)
    c = simulate(model, 1000, 100.0, seed=43)
    assert a.shape == (1000, 6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # per-sample std of white noise N at fs is N sqrt(fs) (continuous -> discrete)
    big = simulate(model, 200_000, 100.0, seed=1)
    assert np.std(big[:, 0]) == pytest.approx(1e-3 * 10.0, rel=0.01)


def test_simulate_rejects_bad_arguments():
    model = NoiseModel({'gyro_x': {'white_noise': 1e-3}})
    with pytest.raises(ValueError):
        simulate(model, 10, 0.0)
    with pytest.raises(ValueError):
        simulate(model, -1, 100.0)
