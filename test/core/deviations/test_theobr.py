"""
Theo1's automatic noise type and bias removal (ThêoBR, :mod:`.theobr`) against Stable32.

Stable32 prints Theo1 with the noise left on automatic as Theo1 x k, k the data's mean ratio
AVAR / Theo1, with one noise type per run (its PHASE.DAT table headed "Alpha = 1": every row
is the "Alpha = 0" table's value times sqrt(0.60279), alpha 1 on every row).  The values are
compared at rtol 1e-4 (the tables' 5 digits, as the other Stable32 tests), the bounds at rtol
3e-4 through Stable32's own chi-square quantiles (:func:`.stable32.bounds`).  NBS14 1000-point
(PHASE.DAT is its integral) with the noise fixed at white FM gives SP1065 table III's Theo1.
"""

import imu_allan
from imu_allan.core.allan.estimate import _phase
from imu_allan.core.deviations import api, theobr
import numpy as np
import pytest

from .stable32 import bounds, phase_dat, table
from .test_nbs14 import nbs14_1000, TABLE_III

#: Stable32 1.61, PHASE.DAT, Thêo1, octave, "Alpha = 1" (automatic), with its 68.3 % bounds:
#: AF, min, value, max (AllanToolkit's tests/assets/phasedat/theo1_octave.txt).
OCTAVE = np.array([
    [10, 8.1377e-02, 8.3520e-02, 8.5842e-02],
    [20, 5.4999e-02, 5.6492e-02, 5.8114e-02],
    [40, 3.6714e-02, 3.7773e-02, 3.8929e-02],
    [80, 2.6879e-02, 2.7731e-02, 2.8670e-02],
    [160, 2.1431e-02, 2.2204e-02, 2.3067e-02],
    [320, 1.2841e-02, 1.3389e-02, 1.4015e-02],
    [640, 7.8907e-03, 8.3333e-03, 8.8605e-03],
])


def test_automatic_theo1_is_stable32s_table():
    # All 181 rows of the automatic table through the public API: value, alpha, '#'.
    rows = table('phase_dat_theo1.txt')
    result = imu_allan.deviation(phase_dat(), 1.0, 'theo1', taus=rows['tau'])
    np.testing.assert_array_equal(result.m, rows['m'])
    np.testing.assert_allclose(result.dev[:, 0], rows['dev'], rtol=1e-4)
    np.testing.assert_array_equal(result.alpha[:, 0], rows['alpha'])
    np.testing.assert_allclose(result.n_terms, rows['n'], rtol=5e-5)  # printed to 5 digits


def test_the_constant_is_the_data_ratio():
    # Stable32's two tables differ by one constant (the square of their ratio is 0.60279 on
    # every row, to their rounding), and it is ThêoBR's k of these data, which labels them
    # flicker PM (nominal 0.6) although they are white FM.
    auto, fixed = table('phase_dat_theo1.txt'), table('phase_dat_theo1_alpha0.txt')
    np.testing.assert_array_equal(auto['m'], fixed['m'])
    squared = (auto['dev'] / fixed['dev']) ** 2
    k = api.run_bias('theo1', _phase(phase_dat()), phase_dat())[1]
    assert 1.0 / k[0] == pytest.approx(0.60279, rel=1e-4)
    np.testing.assert_allclose(squared, 1.0 / k[0], rtol=2e-4)
    assert theobr.nominal_alpha(1.0 / k)[0] == 1


def test_automatic_bounds_are_stable32s():
    # Theo1's EDF (Howe & Peppler) at the run's noise gives Stable32's printed bounds.
    result = imu_allan.deviation(phase_dat(), 1.0, 'theo1', taus=0.75 * OCTAVE[:, 0])
    np.testing.assert_allclose(result.dev[:, 0], OCTAVE[:, 2], rtol=1e-4)
    low, high = bounds(result.dev[:, 0], result.edf[:, 0])
    np.testing.assert_allclose(low, OCTAVE[:, 1], rtol=3e-4)
    np.testing.assert_allclose(high, OCTAVE[:, 3], rtol=3e-4)


def test_nbs14_white_fm_fixed_is_table_iii():
    # The published Theo1 (SP1065 table III; Stable32's "Alpha = 0" table) is Theo1 with the
    # noise fixed at white FM, whose Howe-Tasset bias is 1: AF 10, 100, 1000.
    result = imu_allan.deviation(nbs14_1000(), 1.0, 'theo1', taus=[7.5, 75.0, 750.0], alpha=0)
    np.testing.assert_array_equal(result.m, [10, 100, 1000])
    np.testing.assert_allclose(result.dev[:, 0], TABLE_III['theo1'], rtol=1e-4)
    assert np.all(result.alpha == 0)
    # ... and automatic, what Stable32 prints on the same data (PHASE.DAT is its integral).
    auto = imu_allan.deviation(nbs14_1000(), 1.0, 'theo1', taus=[7.5, 75.0])
    np.testing.assert_allclose(auto.dev[:, 0], [8.3520e-02, 2.4681e-02], rtol=1e-4)


def test_fixed_alpha_reproduces_whole_stable32_tables():
    # Stable32's totdev and oadev tables print alpha 0 on every row; with it fixed the public
    # API gives every value and bound, including m = 128 and 256, where the identification
    # from 16 and 8 block means differs from Stable32's (docs/method.md section 8).
    for kind in ('totdev', 'oadev'):
        rows = table(f'phase_dat_{kind}_octave.txt')
        assert np.all(rows['alpha'] == 0)
        result = imu_allan.deviation(phase_dat(), 1.0, kind, taus=rows['tau'], alpha=0)
        np.testing.assert_allclose(result.dev[:, 0], rows['dev'], rtol=1e-4)
        low, high = bounds(result.dev[:, 0], result.edf[:, 0])
        np.testing.assert_allclose(low, rows['low'], rtol=3e-4)
        np.testing.assert_allclose(high, rows['high'], rtol=3e-4)


@pytest.mark.parametrize('kind, alpha', [('adev', 3), ('adev', -3), ('ohdev', -5),
                                         ('theo1', 1.5), ('mdev', '1'), ('totdev', None)])
def test_fixed_alpha_outside_the_range_is_named(kind, alpha):
    data = np.random.default_rng(0).standard_normal((2000, 1))
    if alpha is None:  # the default: identified, no error
        imu_allan.deviation(data, 1.0, kind, alpha=alpha)
        return
    with pytest.raises(ValueError, match=f'alpha must be a whole number .* for {kind}'):
        imu_allan.deviation(data, 1.0, kind, alpha=alpha)


def test_nominal_boundaries_are_geometric_means():
    nominal = theobr.NOMINAL
    for alpha, k in nominal.items():
        assert theobr.nominal_alpha([k])[0] == alpha
    edge = np.sqrt(nominal[0] * nominal[-1])  # white FM | flicker FM
    np.testing.assert_array_equal(theobr.nominal_alpha([edge * 0.999, edge * 1.001]), [0, -1])
    np.testing.assert_array_equal(theobr.nominal_alpha([np.nan, 1e-9, 1e9]), [0, 2, -2])


def test_white_pm_is_named_on_every_record():
    # A generator of this test: first differences of white noise (white PM, the quantization
    # of an IMU).  k is about 0.15 on 2000 samples (measured, seed 4: 0.13-0.17 over the 20
    # records), far below the white PM | flicker PM boundary 0.49: every record is white PM.
    y = np.diff(np.random.default_rng(4).standard_normal((2001, 20)), axis=0)
    alpha, factor = api.run_bias('theo1', _phase(y), y)
    np.testing.assert_array_equal(alpha, 2)
    assert np.all((1.0 / factor > 0.1) & (1.0 / factor < 0.25))


def test_sampled_mean_is_close_to_the_exact(monkeypatch):
    # Above EXACT_WORK the mean is taken over 32 ratios, Theo1 thinned.  On 2500 samples of
    # random-walk FM and white FM (generators of this test, seed 9) it stays within 5 % of the
    # mean of all 414 ratios (measured over 32 records of 3000 and 6000 samples and four noises:
    # at most 3.3 %, the noise class always the same; the exact k itself ranged 0.75-1.65 on
    # white FM records, so 5 % is small against its own scatter).
    r = np.random.default_rng(9)
    y = np.column_stack([np.cumsum(r.standard_normal(2500)), r.standard_normal(2500)])
    x = _phase(y)
    assert theobr.plan(x.shape[1])[0].size == theobr.SAMPLES
    sampled = api.run_bias('theo1', x, y)
    monkeypatch.setattr(theobr, 'EXACT_WORK', np.inf)
    assert theobr.plan(x.shape[1])[0].size == 414  # i = 0 .. 2501 // 6 - 3
    exact = api.run_bias('theo1', x, y)
    np.testing.assert_allclose(sampled[1], exact[1], rtol=0.05)
    np.testing.assert_array_equal(sampled[0], exact[0])


def test_compiled_and_numpy_thinned_theo1_agree():
    from imu_allan.core.deviations import theo, total_kernel
    x = _phase(np.random.default_rng(1).standard_normal((3000, 2)))
    ms, strides = np.array([12, 100, 1000]), np.array([1, 7, 50])
    np.testing.assert_allclose(total_kernel.variance('theo1', x, ms, strides),
                               theo.theo1_fast(x, ms, strides), rtol=1e-12)


def test_short_record_falls_back_to_white_fm():
    # Under 19 phase points no ratio exists: white FM, no correction (Theo1 unbiased there).
    y = np.random.default_rng(2).standard_normal((16, 1))
    result = imu_allan.deviation(y, 1.0, 'theo1')
    raw = np.sqrt(api.raw_variance('theo1', _phase(y), result.m))
    np.testing.assert_allclose(result.dev, raw, rtol=1e-12)
    assert np.all(result.alpha == 0)
