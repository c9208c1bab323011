"""
Overlapping Allan deviation, its averaging-time grid and its confidence intervals.

Oracles: NBS14 10-point data set (allantools' Stable32-checked test, anchors 10.4), the
Greenhall-Riley EDF values of anchors 10.2, and allantools itself on random data.
"""

import math
import subprocess
import sys

import allantools
from imu_allan import allan_deviation
from imu_allan.core.allan import kernel as allan_kernel
from imu_allan.core.allan.edf import chi2_interval, edf_oadev
from imu_allan.core.allan.estimate import (
    avar_fast,
    avar_function,
    avar_reference,
    identify_noise,
    tau_grid,
)
import numpy as np
import pytest

NBS14_FREQ = [892, 809, 823, 798, 671, 644, 883, 903, 677]


def test_nbs14_overlapping_adev_to_1e4():
    result = allan_deviation(NBS14_FREQ, 1.0, taus=[1.0, 2.0])
    np.testing.assert_allclose(result.adev[:, 0], [91.22945, 85.95287], rtol=1e-4)


def test_nbs14_from_phase_matches():
    # The same data given as phase (anchors 10.4): differencing it gives the frequencies.
    phase = [0, 103.11111, 123.22222, 157.33333, 166.44444, 48.55555, -96.33333, -2.22222,
             111.88889, 0]
    freq = np.diff(phase) + np.mean(NBS14_FREQ)
    result = allan_deviation(freq, 1.0, taus=[1.0, 2.0])
    np.testing.assert_allclose(result.adev[:, 0], [91.22945, 85.95287], rtol=1e-4)


def test_fast_path_equals_reference():
    rng = np.random.default_rng(5)
    data = rng.standard_normal((50_000, 3)) * [1e-3, 2e-3, 3e-2] + [0.0, 0.1, 9.81]
    ms = tau_grid(50_000, 20, 4)
    np.testing.assert_allclose(avar_fast(data, ms), avar_reference(data, ms), rtol=1e-10)


def test_kernel_choice_by_size():
    """Short records take the numpy reference, long ones the compiled kernel."""
    assert avar_function(6000 * 6 * 25) is avar_reference       # one minute at 100 Hz
    assert avar_function(360_000 * 6 * 43) is allan_kernel.avar  # one hour


def test_short_record_does_not_import_numba():
    """
    A one-minute record in a fresh interpreter never imports numba.

    Importing it and loading the kernel take 0.5-1 s, more than the whole estimate with numpy.
    """
    code = ('import sys; import numpy as np; from imu_allan import allan_deviation; '
            'allan_deviation(np.random.default_rng(0).normal(size=(6000, 6)), 100.0); '
            "print('numba' in sys.modules)")
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == 'False'


def test_agrees_with_allantools_oadev():
    rng = np.random.default_rng(6)
    y = rng.standard_normal(20_000) * 0.01 + np.cumsum(rng.standard_normal(20_000)) * 1e-4
    taus = np.array([0.01, 0.05, 0.3, 1.0, 7.0, 20.0])
    ours = allan_deviation(y, 100.0, taus=taus)
    _, theirs, _, _ = allantools.oadev(y, rate=100.0, data_type='freq', taus=taus)
    np.testing.assert_allclose(ours.adev[:, 0], theirs, rtol=1e-8)


def test_offset_does_not_change_adev():
    # The mean is removed before integration: a 1 g offset must not cost precision.
    rng = np.random.default_rng(7)
    y = rng.standard_normal(100_000) * 1e-3
    a = allan_deviation(y, 100.0).adev
    b = allan_deviation(y + 9.80665, 100.0).adev
    np.testing.assert_allclose(a, b, rtol=1e-9)


def test_tau_grid_log_spacing_and_cluster_guard():
    ms = tau_grid(100_000, points_per_decade=10, min_clusters=10)
    assert ms[0] == 1 and ms[-1] == 10_000
    assert np.all(np.diff(ms) > 0)
    ratios = ms[1:] / ms[:-1]
    assert ratios[-10:].max() < 10 ** 0.11  # ~10 per decade once integers are dense enough
    dense = tau_grid(100_000, points_per_decade=30, min_clusters=10)
    assert dense.size > 2 * ms.size
    assert tau_grid(9, 10, 10).size == 0  # not even one cluster of 10: no averaging time


def test_result_shapes_and_axes():
    data = np.random.default_rng(1).standard_normal((10_000, 6))
    r = allan_deviation(data, 200.0)
    t = r.tau.size
    assert r.adev.shape == r.ci_low.shape == r.ci_high.shape == r.edf.shape == (t, 6)
    assert r.axes[0] == 'gyro_x' and r.axes[-1] == 'accel_z'
    np.testing.assert_allclose(r.tau, r.m / 200.0)
    assert np.all(r.ci_low < r.adev) and np.all(r.adev < r.ci_high)


@pytest.mark.parametrize('alpha,n,m,expected', [
    (0, 1000, 1, 781.25), (0, 1000, 10, 134.93), (0, 1000, 100, 12.80),
    (0, 100000, 1000, 147.75), (-1, 100000, 1000, 115.54), (-2, 100000, 1000, 91.14),
    (2, 1000, 10, 506.66)])
def test_greenhall_edf_oracle_values(alpha, n, m, expected):
    # Where Greenhall & Riley use a fitted table (J > 100) we sum exactly: 0.1 % apart.
    assert edf_oadev(alpha, m, n) == pytest.approx(expected, rel=1e-3)


def test_edf_matches_allantools_where_both_are_exact():
    for alpha in (2, 1, 0, -1, -2):
        for m in (1, 3, 10, 30):
            theirs = allantools.edf_greenhall(alpha=alpha, d=2, m=m, N=5000,
                                              overlapping=True, modified=False)
            assert edf_oadev(alpha, m, 5000) == pytest.approx(theirs, rel=1e-9)
    # white PM on a record of M <= m second differences: no two share a phase point, so the
    # EDF is M (the paper's short-record sum, which allantools leaves unimplemented)
    assert edf_oadev(2, 1000, 3000) == 1000.0


@pytest.mark.parametrize('alpha', [0, -1, -2])
def test_long_lag_sums_are_within_their_stated_accuracy_of_the_exact_sums(alpha):
    """Above 4096 lags the EDF's sums are integrated: 7e-7 at m = 1366, 6e-8 from m = 5000."""
    from imu_allan.core.allan.edf import _lag_sums, _sz
    for m, tolerance in [(1366, 7e-7), (5000, 6e-8), (40_000, 6e-8)]:
        j_count = 3 * m
        j = np.arange(1.0, j_count)
        sz_sq = _sz(j / m, math.inf, alpha, 2) ** 2
        exact = [np.sum(sz_sq), np.sum(j * sz_sq)]
        got = _lag_sums(j_count, m, math.inf, alpha, 2, (None, lambda j: j))
        np.testing.assert_allclose(got, exact, rtol=tolerance)
        m_short = int(2.5 * m)  # a record with M < 3m: the sum stops between the kinks
        w = 1.0 - j[:m_short - 1] / m_short
        exact = np.sum(w * sz_sq[:m_short - 1])
        got = _lag_sums(m_short, m, math.inf, alpha, 2,
                        (lambda j, big_m=m_short: 1.0 - j / big_m,))[0]
        assert got == pytest.approx(exact, rel=tolerance)


def test_chi2_interval_for_edf_100():
    low, high = chi2_interval(1.0, 100.0)
    assert low == pytest.approx(0.93619, abs=2e-5)
    assert high == pytest.approx(1.07892, abs=2e-5)


def test_noise_identification_picks_the_dominant_term():
    tau = np.logspace(-2, 4, 30)  # white up to 100 s, flicker 100-1000 s, random walk after
    avar = 1e-6 / tau + 1e-8 + 1e-11 * tau
    alpha = identify_noise(tau, avar[:, None])[:, 0]
    assert alpha[0] == 0 and alpha[-1] == -2
    assert -1 in alpha


def test_interval_width_shrinks_with_data():
    rng = np.random.default_rng(2)
    short = allan_deviation(rng.standard_normal(10_000), 100.0, taus=[1.0])
    long = allan_deviation(rng.standard_normal(100_000), 100.0, taus=[1.0])
    width = lambda r: (r.ci_high - r.ci_low)[0, 0] / r.adev[0, 0]  # noqa: E731
    assert width(long) < width(short) / 2.5  # ~ sqrt(10) narrower


def test_white_noise_adev_level_is_unbiased():
    # density 0.0025 at 400 Hz, 1 h (anchors pitfall 1): the stride-1 estimator gives N at 1 s.
    rng = np.random.default_rng(3)
    n = 400 * 3600
    y = 0.0025 * math.sqrt(400.0) * rng.standard_normal(n)
    r = allan_deviation(y, 400.0, taus=[1.0])
    assert r.ci_low[0, 0] < 0.0025 < r.ci_high[0, 0]
    assert r.adev[0, 0] == pytest.approx(0.0025, rel=0.02)


def test_from_avar_keeps_orientation_when_taus_equal_axes():
    """(T, A) with T == A is taken as given (it used to be transposed); shapes checked."""
    from imu_allan.core.allan.estimate import AllanResult
    rng = np.random.default_rng(3)
    ms = np.array([1, 2, 4, 8, 16, 32])
    avar = rng.uniform(1.0, 2.0, (6, 6)) / ms[:, None]  # column j: axis j
    res = AllanResult.from_avar(ms, avar, 100_000, 100.0)
    np.testing.assert_array_equal(res.avar, avar)
    one_axis = AllanResult.from_avar(ms, avar[:, 0], 100_000, 100.0)
    assert one_axis.avar.shape == (6, 1)
    with pytest.raises(ValueError, match='rows'):
        AllanResult.from_avar(ms[:5], avar, 100_000, 100.0)


def test_too_few_samples_message_states_what_the_grid_needs():
    """The error names exactly the count at which the first averaging time appears."""
    from imu_allan.core.allan.estimate import min_record, tau_grid
    need = min_record(10)
    assert tau_grid(need - 1).size == 0 and tau_grid(need).size == 1
    with pytest.raises(ValueError, match=f'need at least {need}'):
        allan_deviation(np.zeros((need - 1, 1)) + np.arange(need - 1)[:, None], 100.0)
