"""Thesis preprocessing: Tukey outlier replacement, time-stamp gaps and jitter, units."""


from imu_allan.core.checks.preprocess import check_timing, replace_outliers, tukey_fences
import numpy as np
import pytest


def test_tukey_replaces_extreme_outliers_with_inlier_mean_and_counts_them():
    rng = np.random.default_rng(0)
    data = rng.standard_normal((10_000, 2))
    data[[10, 500], 0] = [50.0, -40.0]
    data[7, 1] = 30.0
    clean, report = replace_outliers(data, ('gyro_x', 'gyro_y'))
    assert report.counts == {'gyro_x': 2, 'gyro_y': 1}
    assert report.total == 3
    assert list(report.indices['gyro_x']) == [10, 500]
    inliers = np.delete(data[:, 0], [10, 500])
    assert clean[10, 0] == pytest.approx(inliers.mean())
    np.testing.assert_array_equal(np.delete(clean[:, 0], [10, 500]), inliers)
    assert data[10, 0] == 50.0  # the input is not modified


def test_tukey_fences_use_f3():
    values = np.arange(1.0, 101.0)
    q1, q3 = np.percentile(values, [25, 75])
    lo, hi = tukey_fences(values)
    assert lo == pytest.approx(q1 - 3 * (q3 - q1))
    assert hi == pytest.approx(q3 + 3 * (q3 - q1))


def test_gaussian_noise_has_almost_no_tukey_outliers():
    # F = 3 fences sit at 4.72 sigma: ~2.4e-6 per sample.
    data = np.random.default_rng(1).standard_normal((200_000, 1))
    _, report = replace_outliers(data, ('gyro_x',))
    assert report.total <= 5


def test_timing_gaps_jitter_rate():
    t = np.arange(0, 1000) * 0.01
    t = np.delete(t, np.r_[100:105, 700])  # 5 missing, then 1 missing
    rep = check_timing(t)
    assert rep.rate_hz == pytest.approx(100.0)
    assert rep.n_gaps == 2
    assert rep.missing_samples == 6
    assert rep.longest_gap_s == pytest.approx(0.06)
    assert rep.jitter == pytest.approx(0.0, abs=1e-9)
    noisy = np.arange(0, 1000) * 0.01 + np.random.default_rng(2).normal(0, 1e-4, 1000)
    assert check_timing(noisy).jitter == pytest.approx(0.014, rel=0.2)


def test_timing_counts_non_increasing_steps():
    t = np.array([0.0, 0.01, 0.02, 0.02, 0.015, 0.03])
    assert check_timing(t).n_nonincreasing == 2
    with pytest.raises(ValueError):
        check_timing(np.array([1.0]))
