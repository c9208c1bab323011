"""
Overbounding (core/overbound.py): the consumer model's AVAR above the measured upper bound.

One simulated record (white noise N, bias instability B, rate random walk K on x; the same plus a
Gauss-Markov on z; 100 Hz, 400 s, seed 7).  The checks are properties the linear program must
have, not numbers copied from its output:

* feasibility: the model's analytic AVAR (``core/terms.py``) is >= the 95 % upper bound at every
  averaging time up to the horizon, recomputed here from ``chi2_interval``;
* minimality: at least one constraint is tight, and scaling the solution down by 1 % violates
  the bound (so nothing is left on the table along the solution's direction); for white +
  random walk, the LP optimum is no worse than a brute-force grid over (N^2, K^2);
* the horizon: the shorter horizon's optimum is no worse there than the full one's; one
  outside the measured range is a ValueError;
* a white + random walk model must lift N above the raw fit where bias instability dominates,
  and a model with the flicker term bounds more tightly (smaller objective).
"""

import math

import imu_allan
from imu_allan.core.allan.edf import chi2_interval
from imu_allan.core.model import NoiseModel
from imu_allan.core.overbound import overbound, overbound_axes, upper_bound, white_overbound
from imu_allan.core.terms import model_avar
import numpy as np
import pytest

RATE = 100.0
WHITE_WALK = ('white_noise', 'rate_random_walk')
GM_MODEL = ('white_noise', 'gauss_markov')


@pytest.fixture(scope='module')
def result():
    base = {'white_noise': {'value': 1e-3}, 'bias_instability': {'value': 3e-3},
            'rate_random_walk': {'value': 3e-4}}
    truth = NoiseModel({'gyro_x': base,
                        'gyro_z': {**base, 'gauss_markov': {'sigma': 3e-3, 'tau_c': 2.0}}}, RATE)
    data = imu_allan.simulate(truth, 40_000, RATE, seed=7, axes=['gyro_x', 'gyro_z'])
    return imu_allan.allan_deviation(data, RATE, axes=('gyro_x', 'gyro_z'))


def _bound(result, axis, horizon=None):
    j = result.axis_index(axis)
    high = chi2_interval(result.adev[:, j], result.edf[:, j], level=0.95)[1] ** 2
    keep = result.tau <= (horizon or result.tau[-1]) * (1 + 1e-9)
    return result.tau[keep], high[keep]


@pytest.mark.parametrize('axis', ['gyro_x', 'gyro_z'])
@pytest.mark.parametrize('shapes', [WHITE_WALK, GM_MODEL,
                                    ('white_noise', 'bias_instability', 'rate_random_walk')])
def test_model_lies_above_bound_and_is_tight(result, axis, shapes):
    fit = overbound_axes(result, axis, shapes)
    tau, bound = _bound(result, axis)
    model = model_avar(fit.terms, tau, RATE)
    assert np.all(model >= bound * (1 - 1e-9))
    assert fit.tight_tau, 'an LP optimum has an active constraint'
    scaled = {t: {k: (v * 0.99 if k != 'tau_c' else v) for k, v in p.items()}
              for t, p in fit.terms.items()}
    assert np.any(model_avar(scaled, tau, RATE) < bound)
    assert fit.objective >= 1.0


def test_white_walk_optimum_beats_a_grid(result):
    fit = overbound_axes(result, 'gyro_x', WHITE_WALK)
    tau, bound = _bound(result, 'gyro_x')
    n2 = fit.value('white_noise') ** 2 * np.geomspace(0.3, 3.0, 61)
    k2 = fit.value('rate_random_walk') ** 2 * np.geomspace(0.3, 3.0, 61)
    best = math.inf
    for a in n2:
        for b in k2:
            m = a / tau + b * (tau / 3 + 1 / (6 * RATE ** 2 * tau))
            if np.all(m >= bound):
                best = min(best, float(np.mean(m / bound)))
    assert fit.objective <= best * (1 + 1e-6)


def test_white_walk_is_lifted_where_bias_instability_dominates(result):
    raw = imu_allan.fit_noise_model(result)
    fit = overbound_axes(result, 'gyro_x', WHITE_WALK)
    # the flat flicker floor (0.664 B) must be covered by N^2/tau + K^2 tau/3, whose minimum
    # 2 N K / sqrt(3) is far below it with the raw N: N has to grow
    assert fit.value('white_noise') > 1.3 * raw.value('gyro_x', 'white_noise')
    with_flicker = overbound_axes(result, 'gyro_x',
                                  ('white_noise', 'bias_instability', 'rate_random_walk'))
    assert with_flicker.objective < fit.objective


def test_horizon(result):
    full = overbound_axes(result, 'gyro_x', WHITE_WALK)
    short = overbound_axes(result, 'gyro_x', WHITE_WALK, horizon_s=1.0)
    assert short.tau[-1] <= 1.0 + 1e-9 and short.horizon_s == 1.0
    # the full-horizon solution is feasible for the shorter one, so it cannot do better there
    full_there = model_avar(full.terms, short.tau, RATE) / short.bound
    assert np.all(full_there >= 1 - 1e-9)
    assert short.objective <= float(np.mean(full_there)) * (1 + 1e-9)
    for bad in (result.tau[0] / 2, result.tau[-1] * 2, math.nan):
        with pytest.raises(ValueError, match='horizon'):
            upper_bound(result, 'gyro_x', bad)


def test_envelope_bounds_every_axis(result):
    fit = overbound_axes(result, ['gyro_x', 'gyro_z'], GM_MODEL)
    for axis in ('gyro_x', 'gyro_z'):
        tau, bound = _bound(result, axis)
        assert np.all(model_avar(fit.terms, tau, RATE) >= bound * (1 - 1e-9))


def test_refuses_what_it_cannot_profile(result):
    tau, bound, _ = upper_bound(result, 'gyro_x')
    with pytest.raises(ValueError, match='sinusoid'):
        overbound(tau, bound, ('white_noise', 'sinusoid'), RATE)


def test_white_overbound_is_the_largest_tau_times_bound(result):
    n = white_overbound(result, ['gyro_x', 'accel_q', 'gyro_z'])
    assert math.isnan(n[1])
    for value, axis in ((n[0], 'gyro_x'), (n[2], 'gyro_z')):
        tau, bound = _bound(result, axis)
        # one term: the LP's optimum is the smallest N^2 with N^2 / tau >= bound everywhere
        assert value ** 2 == pytest.approx(float(np.max(bound * tau)), rel=1e-6)
