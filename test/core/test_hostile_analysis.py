"""
Hostile samples at the analysis: no silent wrong answer.

Non-finite and non-physical values (beyond ``units.PHYSICAL_LIMIT``) are refused naming the
axis, value, sample and stamp; the outlier report says ``replaced`` only when asked; lost
samples are counted from the true interval even when most steps are multiples of it.
Records are 2,000 samples (well under a second each).
"""

from imu_allan.core.analysis import AnalysisOptions, analyze_samples
from imu_allan.core.checks.preprocess import check_timing, nominal_interval
from imu_allan.core.units import PHYSICAL_LIMIT
from imu_allan.errors import InputError
from imu_allan.formats.samples import Samples
from imu_allan.report.json_report import analysis_to_json
import numpy as np
import pytest

N = 2000


def _samples(seed=0):
    rng = np.random.default_rng(seed)
    return Samples(t=100.0 + np.arange(N) / 100.0, data=rng.normal(0.0, 1e-3, (N, 6)),
                   source='rec')


@pytest.mark.parametrize('seed', range(6))
def test_non_physical_or_non_finite_values_are_named_and_refused(seed):
    """Seeded positions and magnitudes from just beyond the limit to inf: one line naming it."""
    rng = np.random.default_rng(seed)
    s = _samples(seed)
    i, j = int(rng.integers(0, N)), int(rng.integers(0, 6))
    limit = PHYSICAL_LIMIT['gyro' if j < 3 else 'accel']
    value = [limit * 1.01, -1e130, 1e200, np.inf, -np.inf, np.nan][seed]
    s.data[i, j] = value
    with pytest.raises(InputError) as info:
        analyze_samples(s)
    text = str(info.value)
    assert s.axes[j] in text and f'sample {i} ' in text and f't={s.t[i]:.6f}' in text
    assert ('non-physical' in text) == bool(np.isfinite(value))


def test_values_at_the_limit_are_kept():
    """The limit is far beyond real sensors: a record up to it is analysed, not refused."""
    s = _samples()
    s.data[10, 0] = PHYSICAL_LIMIT['gyro']
    s.data[20, 5] = -PHYSICAL_LIMIT['accel']
    assert analyze_samples(s).n_samples == N


def test_outliers_replaced_only_when_asked():
    """With outliers present, ``replaced`` is false by default and true with the option."""
    s = _samples()
    s.data[::97, 0] += 0.05  # Tukey F=3 outliers
    plain = analysis_to_json(analyze_samples(s))['outliers']
    assert plain['counts']['gyro_x'] > 0 and plain['replaced'] is False
    asked = analysis_to_json(analyze_samples(s, AnalysisOptions(replace_outliers=True)))
    assert asked['outliers']['replaced'] is True


@pytest.mark.parametrize('loss, seed', [(0.3, 1), (0.42, 2), (0.45, 3)])
def test_lost_samples_counted_from_the_true_interval(loss, seed):
    """Losing more than half of every other sample doubles the median step: not 50 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 100.0
    keep = np.ones(N, bool)
    keep[1::2] = rng.random(N // 2) > 2 * loss  # loss concentrated on odd samples
    timing = check_timing(t[keep])
    assert timing.rate_hz == pytest.approx(100.0)
    assert timing.missing_samples == N - keep.sum() - (not keep[-1])


def test_nominal_interval_leaves_jittery_stamps_alone():
    """Host stamps with +-20 % jitter and no loss: the median, not a sub-multiple."""
    steps = 0.01 * (1 + np.random.default_rng(4).uniform(-0.2, 0.2, 5000))
    assert nominal_interval(steps) == pytest.approx(0.01, rel=0.01)


@pytest.mark.parametrize('low, share, expected', [
    (0.5, 0.20, 0.5),       # a fifth of the steps at median / 2: the interval is half of it
    (0.5, 0.14, 1.0),       # under the 15 % share: the median
    (0.549, 0.16, 0.549),   # near the far edge of median / 2's tolerance: still counted
    (0.5505, 0.30, 1.0),    # just past it (and no other sub-multiple): the median
])
def test_nominal_interval_sub_multiples_at_the_edges(low, share, expected):
    """The one-pass shortcut (too few steps near any sub-multiple) changes no answer."""
    n = 10_000
    steps = np.ones(n)
    steps[:int(share * n)] = low
    assert nominal_interval(steps) == expected
