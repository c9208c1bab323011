"""
Calibration of the fit on simulated records with known truth (calibration_cases.py).

The full table (1 h and 3 h, 100 and 400 Hz, >= 120 cases per term) is printed by
``python test/core/calibration_cases.py`` and kept in docs/method.md; here a smaller batch of
the same cells at 1 h and 100 Hz (both generators, five scenarios, 10 axes each: 100 axes,
~2 min of CPU) checks the goals, with tolerances stated per check.  Plus fast checks of the
interval and alternatives API.
"""

import math

from core.calibration_cases import run, summary
from imu_allan import allan_deviation, fit_noise_model, NoiseModel, simulate
from imu_allan.core.allan.edf import CI_LEVEL
from imu_allan.core.fit import coefficient_interval, Problem, ramp_drift_variance
import numpy as np
import pytest

CELLS = [(s, g, 1.0, 100.0) for s in ('N B K', 'N B', 'N K', 'Q N B', 'N B R')
         for g in ('independent', 'package')]


@pytest.fixture(scope='module')
def outcome():
    return summary(run(CELLS, n_axes=10, seed=7))


def _se(p, n):
    return math.sqrt(p * (1.0 - p) / n)


@pytest.mark.slow
def test_selection_and_alternatives(outcome):
    """
    Selected = truth on >= 85 % of axes, truth selected or an alternative on >= 97 %.

    Over 100 axes a true rate of 90 % (what the full table measures) falls below 85 % with
    probability ~5 %; the fixed seed makes the test deterministic, the margin says it is fair.
    """
    assert outcome['exact'] >= 0.85, outcome
    assert outcome['among'] >= 0.97, outcome


def test_interval_coverage(outcome):
    """
    68.3 % intervals hold the truth 68.3 +- 6 points pooled; 95 % ones >= 91 % pooled.

    Per term the 68.3 % coverage must lie within 3 binomial standard errors of 68.3 % (24-100
    cases per term here, so 3 SE is 14-29 points: this catches a 2x error in width, the full
    table checks the +-6 points) and the 95 % coverage >= 95 % - 3 SE.
    """
    n_all = sum(n for n, _, _ in outcome['cover'].values())
    pooled68 = sum(n * c for n, c, _ in outcome['cover'].values()) / n_all
    pooled95 = sum(n * c for n, _, c in outcome['cover'].values()) / n_all
    assert abs(pooled68 - CI_LEVEL) <= 0.06, outcome
    assert pooled95 >= 0.91, outcome
    for term, (n, c68, c95) in outcome['cover'].items():
        assert abs(c68 - CI_LEVEL) <= 3 * _se(CI_LEVEL, n), (term, n, c68)
        assert c95 >= 0.95 - 3 * _se(0.95, n), (term, n, c95)


#: Realistic records (issue 29): a 1-32-tap window at 1 kHz decimated to 100 Hz, an LSB of
#: 0.2-3 noise sigmas, an aliased line on half of them; the sensor's processing measured.
REALISTIC = [(s, 'realistic', 1.0, 100.0) for s in ('N B K', 'N B', 'N K', 'N B R')]


@pytest.fixture(scope='module')
def realistic():
    return summary(run(REALISTIC, n_axes=25, seed=8))


@pytest.mark.slow
def test_realistic_records_meet_the_goals(realistic):
    """
    On realistic records: selection, alternatives and coverage as on clean ones (100 axes).

    The full table (docs/method.md, 192 axes at 100 Hz and 192 at 200 Hz) meets the goals;
    here the tolerances are those of :func:`test_selection_and_alternatives` and
    :func:`test_interval_coverage` widened for 100 axes: selection >= 80 %, truth among the
    alternatives >= 92 %, pooled 68.3 % coverage within 8 points (its binomial SE over ~220
    cases is 3.1; measured 71.9 %), per term within 3 SE.  With the choice of terms in the
    intervals (issue 35) 40 axes were too few: 80 % on 85 cases there, 2.6 SE from a true
    ~72 % by chance of the draw.
    """
    assert realistic['exact'] >= 0.80, realistic
    assert realistic['among'] >= 0.92, realistic
    n_all = sum(n for n, _, _ in realistic['cover'].values())
    pooled68 = sum(n * c for n, c, _ in realistic['cover'].values()) / n_all
    assert abs(pooled68 - CI_LEVEL) <= 0.08, realistic
    for term, (n, c68, c95) in realistic['cover'].items():
        assert abs(c68 - CI_LEVEL) <= 3 * _se(CI_LEVEL, n), (term, n, c68)
        assert c95 >= 0.95 - 3 * _se(0.95, n), (term, n, c95)


@pytest.fixture(scope='module')
def fitted():
    model = NoiseModel.from_dict({'gyro': {'white_noise': 2e-4, 'bias_instability': 5e-5,
                                           'rate_random_walk': 4e-6}})
    data = simulate(model, 360_000, 100.0, seed=3, axes=['gyro_x'])
    return fit_noise_model(allan_deviation(data, 100.0, axes=['gyro_x']))


def test_interval_levels(fitted):
    """The default level is the stored 68.3 % interval; 95 % contains it; bad levels refused."""
    for term in fitted.model.terms['gyro_x']:
        stored = fitted.intervals['gyro_x'][term]['value']
        assert fitted.interval('gyro_x', term) == stored
        assert fitted.interval('gyro_x', term, 'value') == stored
        lo95, hi95 = fitted.interval('gyro_x', term, level=0.95)
        value = fitted.value('gyro_x', term)
        assert lo95 < stored[0] < value < stored[1] < hi95
    # white noise has thousands of degrees of freedom: chi-square is normal there, and in one
    # named set (no averaging over the choice of terms) the 95 % side is 1.96 standard
    # deviations of the squared coefficient against 1
    named = fit_noise_model(fitted.result, terms=list(fitted.fits['gyro_x'].terms))
    c = named.value('gyro_x', 'white_noise') ** 2
    c_hi = named.interval('gyro_x', 'white_noise')[1] ** 2
    hi95 = named.interval('gyro_x', 'white_noise', level=0.95)[1]
    assert hi95 ** 2 - c == pytest.approx(1.959964 * (c_hi - c), rel=0.03)
    assert all(math.isnan(v) for v in fitted.interval('gyro_x', 'rate_ramp', level=0.95))
    with pytest.raises(ValueError):
        fitted.interval('gyro_x', 'white_noise', level=1.5)


def test_alternatives_start_with_the_selection(fitted):
    alternatives = fitted.alternatives('gyro_x')
    assert alternatives[0] == list(fitted.model.terms['gyro_x'])
    assert len({frozenset(a) for a in alternatives}) == len(alternatives)
    named = fit_noise_model(fitted.result, terms=['white_noise', 'bias_instability'])
    assert named.alternatives('gyro_x') == [['white_noise', 'bias_instability']]


def test_ramp_drift_variance_is_the_noise_slope():
    """
    A random walk K over T shows a slope of sd K / sqrt(T): Var(R^2) = 4 R^2 K^2 T / T'^2.

    (T' = T - 2 tau_max, the span between the end windows.)
    """
    tau = np.geomspace(0.01, 360.0, 40)
    problem = Problem(tau, np.ones(40), np.full(40, 10.0), np.zeros(40), 100.0, 3600.0)
    var = ramp_drift_variance(problem, {'rate_ramp': 4.0, 'rate_random_walk': 1.0})
    assert var == pytest.approx(4 * 4.0 * 3600.0 / (3600.0 - 720.0) ** 2)
    no_length = Problem(tau, np.ones(40), np.full(40, 10.0), np.zeros(40), 100.0)
    assert ramp_drift_variance(no_length, {'rate_ramp': 4.0, 'rate_random_walk': 1.0}) == 0.0


def test_coefficient_interval_of_an_unresolved_term_stays_finite():
    """A term with sd >> c (chi-square quantiles underflow) gets the normal interval, finite."""
    for c, var in ((1.0, 1e6), (1e-12, 1e-20), (1.0, 1e3)):
        lo, hi = coefficient_interval(c, var)
        assert lo == 0.0 and math.isfinite(hi) and hi > math.sqrt(c)
    lo, hi = coefficient_interval(2.0, 0.5, 0.95)  # nu = 16: chi-square, longer upper side
    assert hi - math.sqrt(2.0) > math.sqrt(2.0) - lo > 0


@pytest.mark.parametrize('sd_over_c', [0.1, 1.0, 3.0, 10.0, 100.0, 1e4])
@pytest.mark.parametrize('level', [0.683, 0.95])
def test_coefficient_interval_holds_the_value(sd_over_c, level):
    """
    The interval of sqrt(c) always holds sqrt(c), also where sd >> c.

    With nu = 2 c^2 / var well below 1 the chi-square's upper quantile falls below nu, and the
    chi-square interval would lie entirely above the value (the fleet page drew a negative
    error bar from it); the normal interval takes over there.
    """
    c = 4.0e-6
    lo, hi = coefficient_interval(c, (sd_over_c * c) ** 2, level)
    assert lo <= math.sqrt(c) <= hi
    assert math.isfinite(hi)
