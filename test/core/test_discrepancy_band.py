"""Building blocks of the discrepancy workflow: band, gap calibration, fit, significance."""

import math

from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.discrepancy import (
    excursion_band,
    improvement_test,
    measure_gap,
    model_band,
    run_discrepancy,
)
from imu_allan.core.fit import fit_terms
from imu_allan.core.model import ModelError, NoiseModel
from imu_allan.core.simulation.simulate import simulate
import numpy as np
import pytest

RATE = 100.0
N = 60000  # 10 min
BASE = {'white_noise': {'value': 1e-3}, 'bias_instability': {'value': 3e-4}}


@pytest.fixture(scope='module')
def null_runs():
    """40 independent 10 min records of the base model, 3 axes each (120 curves)."""
    model = NoiseModel({'gyro_x': BASE, 'gyro_y': BASE, 'gyro_z': BASE}, RATE)
    curves = []
    for seed in range(40):
        x = simulate(model, N, RATE, seed=seed)
        curves.append(allan_deviation(x, RATE, axes=model.axes))
    return model, curves


@pytest.mark.slow
def test_gap_is_about_one_for_the_true_model(null_runs):
    """
    Under the true model E[gap^2] = 1 by construction; check it on 120 curves.

    The mean of gap^2 over 120 curves has a standard error of about
    sqrt(2 / T_eff / 120) ~ 0.05 (T_eff ~ 7), so [0.8, 1.2] is a 4-sigma window.
    """
    model, curves = null_runs
    r0 = curves[0]
    band = model_band(BASE, r0.tau, r0.m, r0.n_samples, RATE)
    g2, pvals = [], []
    for r in curves:
        for j in range(3):
            gap = measure_gap(np.log(r.adev[:, j]), band)
            g2.append(gap.value ** 2)
            pvals.append(gap.p_value)
    assert 0.8 < np.mean(g2) < 1.2
    # the chi-square(T_eff) calibration of the consistency test: at most ~1 % should fail at
    # alpha = 1 %; allow 5/120 (binomial P(X >= 5 | 1.2) ~ 1 %)
    assert np.sum(np.array(pvals) < 0.01) <= 5
    # and the p-values are spread (not all near 1: the spread is not overestimated)
    assert 0.3 < np.median(pvals) < 0.75


def test_band_spread_matches_simulation(null_runs):
    """
    The analytic spread of ln(adev) matches the scatter of 120 simulated curves.

    The std of 120 samples has a relative standard error of ~6.5 %; a 25 % band allows for that
    and the EDF approximations at the longest averaging times.
    """
    _, curves = null_runs
    r0 = curves[0]
    band = model_band(BASE, r0.tau, r0.m, r0.n_samples, RATE)
    logs = np.array([np.log(r.adev[:, j]) for r in curves for j in range(3)])
    ratio = logs.std(axis=0) / band.sd
    assert np.all(ratio > 0.75) and np.all(ratio < 1.25), np.round(ratio, 2)
    # the centre includes the log-chi-square bias: mean offset within 4 standard errors
    err = (logs.mean(axis=0) - band.center) / (band.sd / math.sqrt(logs.shape[0]))
    assert np.median(np.abs(err)) < 2.0


def test_fit_recovers_gauss_markov_and_intervals():
    """A fit of WN + BI + GM on a curve with a clear hump recovers tau_c within its interval."""
    truth = {**BASE, 'gauss_markov': {'sigma': 2e-3, 'tau_c': 0.5}}
    x = simulate(NoiseModel({'gyro_x': truth}, RATE), 4 * N, RATE, seed=5)
    r = allan_deviation(x, RATE)
    band = model_band(truth, r.tau, r.m, r.n_samples, RATE)
    fit = fit_terms(band.problem(np.log(r.adev[:, 0]), RATE),
                    ['white_noise', 'bias_instability', 'gauss_markov'])
    lo, hi = fit.intervals95['gauss_markov']['tau_c']
    assert lo <= 0.5 <= hi and hi / lo < 2.0
    lo, hi = fit.intervals95['white_noise']['value']
    assert lo <= 1e-3 <= hi


def test_improvement_test_calibration():
    """Satterthwaite test: pure noise in a correlated residual rarely looks significant."""
    rng = np.random.default_rng(3)
    t = 30
    u = np.arange(t) / 5.0
    corr = np.exp(-np.abs(u[:, None] - u[None, :]) ** 1.5)
    chol = np.linalg.cholesky(corr + 1e-9 * np.eye(t))
    nuisance = np.column_stack([np.ones(t), np.linspace(-1, 1, t)])
    added = np.linspace(0, 1, t)[:, None] ** 2
    hits = 0
    for _ in range(400):
        z = chol @ rng.standard_normal(t)
        q0 = np.sum((z - nuisance @ np.linalg.lstsq(nuisance, z, rcond=None)[0]) ** 2)
        full = np.column_stack([nuisance, added])
        q1 = np.sum((z - full @ np.linalg.lstsq(full, z, rcond=None)[0]) ** 2)
        p, _ = improvement_test(q0 - q1, nuisance, added, corr)
        hits += p < 0.05
    # nominal 5 % of 400 = 20; binomial 99.9 % upper bound ~ 35
    assert hits <= 35
    z = chol @ rng.standard_normal(t) + 40.0 * added[:, 0]
    full = np.column_stack([nuisance, added])
    q0 = np.sum((z - nuisance @ np.linalg.lstsq(nuisance, z, rcond=None)[0]) ** 2)
    q1 = np.sum((z - full @ np.linalg.lstsq(full, z, rcond=None)[0]) ** 2)
    assert improvement_test(q0 - q1, nuisance, added, corr)[0] < 1e-3


def test_excursion_band():
    tau = np.logspace(-2, 2, 41)
    z = np.zeros(41)
    z[20:26] = [2.5, 4, 6, 5, 3, 1.5]
    band, peak = excursion_band(tau, z)
    assert band[0] == pytest.approx(tau[20]) and band[1] == pytest.approx(tau[24])
    assert peak == pytest.approx(tau[22])
    assert excursion_band(tau, np.zeros(41))[0] is None


def test_bad_start_is_a_model_error():
    x = simulate(NoiseModel({'gyro_x': BASE}, RATE), N, RATE, seed=1)
    with pytest.raises(ModelError, match='warp'):
        run_discrepancy(x, RATE, terms=['warp'])
    with pytest.raises(ModelError, match='no terms'):
        run_discrepancy(x, RATE, axes=['gyro_x'], model=NoiseModel({'accel_x': BASE}))
    with pytest.raises(ValueError, match='too short'):
        run_discrepancy(x[:40], RATE)


def test_model_file_with_a_wrong_value_is_recalibrated_not_extended():
    """A datasheet white noise 20 % low is a wrong value, not a missing effect."""
    x = simulate(NoiseModel({'gyro_x': BASE}, RATE), 2 * N, RATE, seed=8)
    start = NoiseModel({'gyro_x': {'white_noise': {'value': 0.8e-3},
                                   'bias_instability': {'value': 3e-4}}})
    result = run_discrepancy(x, RATE, axes=['gyro_x'], model=start, n_sims=1, seed=2)
    assert result.initial_gaps['gyro_x'].value > 5.0  # 20 % off with EDF ~ 1e4 is glaring
    assert result.effects('gyro_x') == ['recalibration']
    step = result.steps[0]
    lo, hi = step.parameters['white_noise']['value']['ci95']
    assert lo <= 1e-3 <= hi
    assert result.final_gaps['gyro_x'].consistent


def test_constant_axis_is_skipped_with_a_note():
    x = simulate(NoiseModel({'gyro_x': BASE}, RATE), N, RATE, seed=1)
    data = np.column_stack([x[:, 0], np.full(N, 0.25)])
    result = run_discrepancy(data, RATE, axes=['gyro_x', 'gyro_y'], n_sims=0)
    assert result.axes == ['gyro_x']
    assert any('gyro_y' in note and 'constant' in note for note in result.notes)
