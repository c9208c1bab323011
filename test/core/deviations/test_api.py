"""The public ``imu_allan.deviation``: grids, rounding, shapes, validation."""

import imu_allan
from imu_allan.core.deviations import grid
import numpy as np
import pytest

RNG = np.random.default_rng(3)
DATA = RNG.standard_normal((20_000, 3)) * [1e-3, 2e-3, 5e-2] + [0.0, 0.01, 9.81]


def test_exported():
    assert imu_allan.deviation is imu_allan.core.deviations.api.deviation
    assert 'deviation' in imu_allan.__all__ and 'DeviationResult' in imu_allan.__all__


def test_oadev_is_allan_deviation():
    # Same grid (min_clusters guard) and the same numbers as allan_deviation.
    result = imu_allan.deviation(DATA, 200.0, 'oadev')
    ref = imu_allan.allan_deviation(DATA, 200.0)
    np.testing.assert_array_equal(result.m, ref.m)
    np.testing.assert_allclose(result.dev, ref.adev, rtol=1e-12)
    assert result.kind == 'oadev' and result.axes == ref.axes and result.n_samples == 20_000


@pytest.mark.parametrize('kind', grid.KINDS)
def test_shapes_and_stop_ratio(kind):
    n = 20_000 if kind not in ('mtotdev', 'htotdev', 'theo1') else 2_000  # O(N m) per m
    result = imu_allan.deviation(DATA[:n], 200.0, kind, points_per_decade=5)
    t, a = result.m.size, 3
    for name in ('dev', 'ci_low', 'ci_high', 'edf', 'alpha'):
        assert getattr(result, name).shape == (t, a), name
    assert np.all(result.ci_low < result.dev) and np.all(result.dev < result.ci_high)
    assert np.all(np.diff(result.m) > 0)
    if kind != 'oadev':
        assert result.m[-1] <= n // grid.STOP_RATIO[kind]
        assert result.m[-1] >= n // grid.STOP_RATIO[kind] * 0.7
    np.testing.assert_allclose(result.tau, result.m * grid.tau_factor(kind) / 200.0)


def test_theo1_even_m_and_tau():
    result = imu_allan.deviation(DATA[:2000], 100.0, 'theo1', taus=[0.075, 0.3, 0.31, 7.5])
    np.testing.assert_array_equal(result.m, [10, 40, 42, 1000])
    np.testing.assert_allclose(result.tau, 0.75 * result.m / 100.0)


def test_taus_round_to_whole_m():
    result = imu_allan.deviation(DATA, 100.0, 'mdev', taus=[0.012, 0.0149, 1.0])
    np.testing.assert_array_equal(result.m, [1, 100])


def test_tdev_is_scaled_mdev():
    mdev = imu_allan.deviation(DATA, 100.0, 'mdev', taus=[0.01, 0.1, 1.0])
    tdev = imu_allan.deviation(DATA, 100.0, 'tdev', taus=[0.01, 0.1, 1.0])
    np.testing.assert_allclose(tdev.dev, mdev.dev * mdev.tau[:, None] / np.sqrt(3.0))
    np.testing.assert_allclose(tdev.ci_high / tdev.dev, mdev.ci_high / mdev.dev)


def test_mdev_and_tdev_together_share_one_estimate():
    # analyze --estimators mdev,tdev: one modified variance, the same numbers as two calls.
    both = imu_allan.core.deviations.extra_deviations(DATA, 100.0, ('tdev', 'mdev'), None,
                                                      5, 10)
    for kind in ('mdev', 'tdev'):
        alone = imu_allan.deviation(DATA, 100.0, kind, points_per_decade=5)
        assert both[kind].kind == kind
        for name in ('dev', 'ci_low', 'ci_high', 'edf', 'alpha', 'tau', 'n_terms'):
            np.testing.assert_array_equal(getattr(both[kind], name), getattr(alone, name))


def test_hadamard_ignores_a_rate_ramp():
    # A linear drift of the rate (rate ramp) adds tau^2 R^2/2 to AVAR but nothing to HVAR:
    # the reason ohdev separates rate random walk from rate ramp.
    t = np.arange(20_000) / 100.0
    drifted = DATA[:, :1] + 1e-3 * t[:, None]
    taus = [1.0, 10.0]
    h0 = imu_allan.deviation(DATA[:, :1], 100.0, 'ohdev', taus=taus).dev
    h1 = imu_allan.deviation(drifted, 100.0, 'ohdev', taus=taus).dev
    a1 = imu_allan.deviation(drifted, 100.0, 'oadev', taus=taus).dev
    np.testing.assert_allclose(h1, h0, rtol=1e-9)
    assert a1[-1, 0] > 10 * h0[-1, 0]


@pytest.mark.parametrize('kwargs, message', [
    ({'kind': 'xdev'}, 'unknown deviation kind'),
    ({'kind': 'mdev', 'taus': [0.001]}, 'shorter than'),
    ({'kind': 'theo1', 'taus': [0.005]}, 'shorter than'),
    ({'kind': 'hdev', 'taus': [150.0]}, 'too long'),
])
def test_bad_input_names_the_problem(kwargs, message):
    with pytest.raises(ValueError, match=message):
        imu_allan.deviation(DATA, 100.0, **kwargs)


def test_nan_and_rate_rejected():
    with pytest.raises(ValueError, match='NaN'):
        imu_allan.deviation([1.0, np.nan, 2.0] * 20, 1.0, 'adev')
    with pytest.raises(ValueError, match='rate_hz'):
        imu_allan.deviation(DATA, 0.0, 'adev')
