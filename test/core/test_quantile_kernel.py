"""
Compiled order statistics for Tukey's fences: the same numbers as numpy, to the bit.

``quartiles`` switches to the kernel from ``KERNEL_ROWS`` rows; the tests lower that bound
so that short arrays, which cover the edge cases, go through the kernel too.
"""

from imu_allan.core.checks import preprocess
from imu_allan.core.checks.quantile_kernel import column_order_stats
import numpy as np
import pytest


def _cases():
    rng = np.random.default_rng(11)
    for n in (1, 2, 3, 4, 5, 8, 101, 4097, 70_001):
        yield f'normal n={n}', rng.normal(size=(n, 3))
    yield 'quantised', np.round(rng.normal(size=(50_000, 6)) * 3) / 7   # many equal values
    yield 'one value', np.full((1000, 2), 3.25)
    spikes = rng.normal(size=(20_000, 2))
    spikes[5, 0], spikes[6, 1] = 1e300, -1e300      # almost every value in one bin
    yield 'huge outliers', spikes
    yield 'gravity', 9.81 + 1e-3 * rng.normal(size=(30_000, 1))
    yield 'strided', rng.normal(size=(9000, 8))[::3, ::2]


@pytest.mark.parametrize('name,data', list(_cases()))
def test_order_statistics_equal_a_sort(name, data):
    n = data.shape[0]
    ranks = np.unique(np.clip([0, n // 4, n // 4 + 1, n // 2, n - 1], 0, n - 1))
    got = column_order_stats(data, ranks)
    assert got is not None, name
    np.testing.assert_array_equal(got, np.sort(data, axis=0)[ranks].T)


@pytest.mark.parametrize('name,data', list(_cases()))
def test_quartiles_equal_numpy_percentile(monkeypatch, name, data):
    monkeypatch.setattr(preprocess, 'KERNEL_ROWS', 0)
    np.testing.assert_array_equal(preprocess.quartiles(data),
                                  np.percentile(data, [25, 75], axis=0).T)


@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_values_are_left_to_numpy(monkeypatch, bad):
    data = np.random.default_rng(2).normal(size=(500, 2))
    data[7, 1] = bad
    assert column_order_stats(data, np.array([100, 101])) is None
    monkeypatch.setattr(preprocess, 'KERNEL_ROWS', 0)
    np.testing.assert_array_equal(preprocess.quartiles(data),
                                  np.percentile(data, [25, 75], axis=0).T)


@pytest.mark.parametrize('column', [[-1.5e308, 0.0, 1.5e308, 2.0],     # max - min overflows
                                    [1e-310, -2e-310, 3e-310, 0.0]])   # bins / width does
def test_overflowing_scale_is_left_to_numpy(monkeypatch, column):
    data = np.array(column)[:, None]
    assert column_order_stats(data, np.array([1, 2])) is None
    monkeypatch.setattr(preprocess, 'KERNEL_ROWS', 0)
    np.testing.assert_array_equal(preprocess.quartiles(data),
                                  np.percentile(data, [25, 75], axis=0).T)


def test_outliers_with_the_kernel_equal_numpy_masks(monkeypatch):
    """replace_outliers: counts, indices, fences and replaced values the same on both paths."""
    rng = np.random.default_rng(5)
    data = rng.normal(size=(40_000, 3))
    data[[3, 900, 39_999], 0] = [40.0, -35.0, 60.0]
    data[17, 2] = np.nan                    # inside the fences, as in numpy comparisons
    axes = ('gyro_x', 'gyro_y', 'gyro_z')
    monkeypatch.setattr(preprocess, 'KERNEL_ROWS', 10**9)
    ref, ref_report = preprocess.replace_outliers(data, axes)
    monkeypatch.setattr(preprocess, 'KERNEL_ROWS', 0)
    got, report = preprocess.replace_outliers(data, axes)
    np.testing.assert_array_equal(got, ref)
    assert report.counts == ref_report.counts == {'gyro_x': 3, 'gyro_y': 0, 'gyro_z': 0}
    np.testing.assert_equal(report.fences, ref_report.fences)     # NaN fences where NaN
    for axis in axes:
        np.testing.assert_array_equal(report.indices[axis], ref_report.indices[axis])
    assert list(report.indices['gyro_x']) == [3, 900, 39_999]
