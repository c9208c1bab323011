"""
The compiled phase, Allan sums and noise identification of ``deviation`` against numpy.

``deviation`` switches to them above :data:`imu_allan.core.allan.estimate.SMALL_WORK`; here the
threshold is moved so that the same short records run both ways.  The noise exponent must be
identical (it is an integer chosen by thresholds the two summation orders cannot move on
these records) and every number equal to 1e-12 relative (the two phases differ by rounding
only, ~1e-16 of the phase).
"""

from imu_allan.core.allan import estimate as allan
from imu_allan.core.deviations import api, noise_id
import numpy as np
import pytest

pytest.importorskip('numba')

RNG = np.random.default_rng(20261125)


def _power_laws(n):
    """Columns: white PM, white FM, random-walk FM, random run, and a mix with an offset."""
    w = RNG.standard_normal((n + 1, 5))
    return np.column_stack([
        np.diff(w[:, 0]), w[1:, 1], np.cumsum(w[1:, 2]), np.cumsum(np.cumsum(w[1:, 3])),
        w[1:, 4] + np.cumsum(RNG.standard_normal(n)) * 0.05 + 9.8])


@pytest.mark.parametrize('dmax', [2, 3])
def test_compiled_noise_id_equals_numpy(dmax):
    from imu_allan.core.deviations import noise_id_kernel
    x = allan._phase(_power_laws(40_000))
    ms = np.array([1, 2, 3, 5, 10, 30, 100, 300, 1000, 1300, 5000, 13_000])
    span = (-4, 2) if dmax == 3 else (-2, 2)
    expected = noise_id.identify_phase(x, ms, dmax, span)
    np.testing.assert_array_equal(noise_id_kernel.identify_phase(x, ms, dmax, span), expected)
    # the five columns are five different laws: the comparison sees more than one alpha
    assert len(np.unique(expected[0])) >= 3


def test_allan_from_the_phase_equals_from_the_samples():
    from imu_allan.core.allan import kernel as allan_kernel
    y = _power_laws(20_001)
    ms = np.array([1, 2, 7, 64, 333, 2000])
    ours = allan_kernel.avar_phase(allan_kernel.phase(y), ms)
    np.testing.assert_array_equal(ours, allan_kernel.avar(y, ms))
    np.testing.assert_allclose(ours, allan.avar_reference(y, ms), rtol=1e-12)
    np.testing.assert_array_equal(allan_kernel.phase_exact(y), allan._phase(y))


@pytest.mark.parametrize('n', [1, 7, 8, 128, 129, 1000, 8193, 40_001])
def test_one_pass_means_equal_numpy_bit_for_bit(n):
    # numpy's pairwise tree changes shape at 8 and 128 values and splits at multiples of 8:
    # lengths around each boundary; a large offset makes every rounding visible.
    from imu_allan.core.allan import kernel as allan_kernel
    y = np.random.default_rng(n).standard_normal((n, 6)) * 1e-3 + 9.80665
    expected = np.array([y[:, a].mean() for a in range(6)])
    np.testing.assert_array_equal(allan_kernel.means_exact(y), expected)
    np.testing.assert_array_equal(allan_kernel.means_exact(y[:, :1].copy()), expected[:1])


@pytest.mark.parametrize('n_phase', [3, 4, 1001, 9001])
def test_compiled_totvar_reflects_like_numpy(n_phase):
    # The compiled TOTVAR reflects the phase on the fly near the ends (numpy: a 3N-point
    # copy, total.reflect): every factor up to N - 2, where both ends are reflected at once,
    # and records longer than a block (4096 points).  (A generator of its own: the module's
    # draws stay those of the tests below.)
    from imu_allan.core.deviations import kernels, total
    x = np.cumsum(np.random.default_rng(n_phase).standard_normal((2, n_phase)), axis=1)
    if n_phase < 9001:
        RNG.standard_normal((2, n_phase))  # the draws this test made before (same data below)
    ms = np.unique(np.round(np.geomspace(1, n_phase - 2, 40))).astype(np.int64)
    np.testing.assert_allclose(kernels.variance('totdev', x, ms), total.totvar(x, ms),
                               rtol=1e-12)
    # the factors in any order (the kernel groups them ascending)
    np.testing.assert_allclose(kernels.variance('totdev', x, ms[::-1]),
                               total.totvar(x, ms[::-1]), rtol=1e-12)


@pytest.mark.parametrize('kind', ['adev', 'oadev', 'mdev', 'tdev', 'hdev', 'ohdev', 'totdev'])
def test_deviation_compiled_equals_numpy(kind, monkeypatch):
    # Not the random run: the compiled MDEV recursion (Stable32's) and numpy's sums differ by
    # ~1e-7 relative on a phase growing as n^2.5 (as before).  The random-walk FM column
    # (index 2, phase ~ n^1.5) at mdev/tdev: the compiled recursion fuses each multiply and
    # add (kernels._CONTRACT), numpy cannot; both orders are off the exact value (long double,
    # direct sums) by 1e-11 to 6e-10 at m = 1 (measured, seeds 3, 17, 18: the recursion's own
    # rounding, the fused one no worse) and differ from each other by up to 2.1e-10 over 20
    # seeds: 1e-9 there; 1e-12 everywhere else (rounding of the phase only).
    y = _power_laws(30_000)[:, [0, 1, 2, 4]]
    monkeypatch.setattr(allan, 'SMALL_WORK', np.inf)
    slow = api.deviation(y, 100.0, kind)
    monkeypatch.setattr(allan, 'SMALL_WORK', 0)
    fast = api.deviation(y, 100.0, kind)
    np.testing.assert_array_equal(fast.alpha, slow.alpha)
    rtol = [1e-12, 1e-12, 1e-9 if kind in ('mdev', 'tdev') else 1e-12, 1e-12]
    for name in ('dev', 'ci_low', 'ci_high', 'edf'):
        for column, tol in enumerate(rtol):
            np.testing.assert_allclose(getattr(fast, name)[:, column],
                                       getattr(slow, name)[:, column], rtol=tol,
                                       err_msg=f'{name}, column {column}')
