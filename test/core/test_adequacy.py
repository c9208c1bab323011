"""
The fit's adequacy test (imu_allan.core.fit.adequacy): calibrated p, power, misfit in words.

Records come from the calibration harness's generators, written there from textbook definitions
and sharing no code with the package (test/core/calibration_cases.py): the independent one for
records the model describes, a moving average decimated (the realistic generator's filter) and a
Gauss-Markov hump for records with an effect the model lacks.
"""

import math

from core import calibration_cases as cc
from imu_allan.core.allan.estimate import AllanResult, avar_fast, tau_grid
from imu_allan.core.allan.log_chi2 import trigamma
from imu_allan.core.fit import ADEQUACY_LEVEL, fit_noise_model
from imu_allan.core.fit.adequacy import misfit_runs
from imu_allan.core.units import AXES
import numpy as np
import pytest
from scipy.signal import lfilter

RATE = 100.0
N = 360_000  # 1 h at 100 Hz


def _fit(data, **kwargs):
    ms = tau_grid(data.shape[0])
    count = data.shape[1]
    result = AllanResult.from_avar(ms, avar_fast(data, ms), data.shape[0], RATE,
                                   axes=AXES[:count])
    return fit_noise_model(result, **kwargs)


@pytest.mark.slow
def test_p_is_uniform_where_the_model_describes_the_record():
    """
    Kolmogorov-Smirnov p > 0.01 for the p-values of 120 records of N B, N K and N B K.

    Fair: under the null the test fails 1 time in 100; the full measurement (docs/method.md,
    "Adequacy": 300 records, p = 0.32) says the distribution is uniform, so a fixed seed that
    fails here means the calibration broke.  Also: none below 0.001 (expected 0.12).
    """
    from scipy.stats import kstest
    rng = np.random.default_rng(21)
    ps = []
    for scenario in ('N B', 'N K', 'N B K') * 40:
        truth = cc.draw_truth(scenario, rng, N, RATE)
        y = cc.independent_axis(truth, N, RATE, rng)
        ps.append(_fit(y[:, None]).adequacy('gyro_x').p)
    assert kstest(ps, 'uniform').pvalue > 0.01, np.quantile(ps, [0.01, 0.1, 0.5, 0.9])
    assert min(ps) >= ADEQUACY_LEVEL


@pytest.mark.slow
def test_a_filter_the_fit_is_not_told_of_is_rejected():
    """
    P below 0.001 on at least 95 % of 40 records whose samples a filter correlates.

    White noise at 1 kHz through a 15-32-tap moving average, every tenth sample kept (the
    realistic generator's filter; window > decimation, so the samples correlate), plus flicker,
    fitted without the sensor's processing: the IEEE shapes cannot bend as the filter does.
    """
    rng = np.random.default_rng(22)
    rejected = 0
    for _ in range(40):
        truth = cc.draw_truth('N B', rng, N, RATE)
        proc = {'taps': int(rng.integers(15, 33)), 'lsb_sigmas': 0.01, 'line': None,
                'decimation': 10}
        y, _ = cc.realistic_axis(truth, N, RATE, rng, proc)
        rejected += _fit(y[:, None], processing=None).adequacy('gyro_x').p < ADEQUACY_LEVEL
    assert rejected >= 38, rejected


@pytest.mark.slow
def test_a_hump_the_model_lacks_is_rejected_and_named():
    """
    P below 0.001 on at least 95 % of 20 records with a Gauss-Markov hump fitted as N + B.

    The hump's Allan deviation peaks at about twice the floor (sigma from the floor, tau_c
    drawn over a decade in the middle of the curve); the misfit span holds the peak.
    """
    rng = np.random.default_rng(23)
    dt = 1.0 / RATE
    rejected, named = 0, 0
    for _ in range(20):
        truth = cc.draw_truth('N B', rng, N, RATE)
        tau_c = math.exp(rng.uniform(math.log(5.0), math.log(50.0)))
        # a Gauss-Markov's Allan deviation peaks at 0.617 sigma (tau = 1.89 tau_c)
        sigma = 2.0 * 0.664 * truth['bias_instability'] / 0.617
        phi = math.exp(-dt / tau_c)
        drive = sigma * math.sqrt(1.0 - phi * phi) * rng.standard_normal(N)
        hump = lfilter([1.0], [1.0, -phi], drive, zi=[phi * sigma * rng.standard_normal()])[0]
        y = cc.independent_axis(truth, N, RATE, rng) + hump
        adequacy = _fit(y[:, None], terms=['white_noise', 'bias_instability']).adequacy('gyro_x')
        if adequacy.p < ADEQUACY_LEVEL:
            rejected += 1
            lo, hi = adequacy.misfit[0].tau_s if adequacy.misfit else (0.0, 0.0)
            named += lo <= 10.0 * tau_c and hi >= 0.3 * tau_c
    assert rejected >= 19, rejected
    assert named >= rejected - 2, (named, rejected)


def test_trigamma_matches_scipy():
    """The variance of ln(chi^2_nu / nu) at nu / 2, to 1e-10 from 0.5 to 1e6 (scipy's)."""
    from scipy.special import polygamma
    x = np.array([0.5, 1.0, 2.3, 5.9, 9.99, 10.0, 17.0, 1e3, 1e6])
    assert np.allclose(trigamma(x), polygamma(1, x), rtol=1e-10, atol=0.0)


def test_misfit_runs_keep_only_runs_with_a_peak():
    """Runs of |z| > 2 of one sign; kept with a point beyond 3.5; the worst first."""
    z = np.array([0.1, 2.5, 3.0, 2.2, 0.0, -2.1, -4.0, -2.4, 1.0, 2.1, 3.6, -2.2, -2.1])
    runs = misfit_runs(np.arange(z.size), z)
    assert runs == [(5, 7, 6), (9, 10, 10)]
