"""
Closed-form Allan variance of every term (anchors 10.1) and the simulator against them.

Then the device processing (window, decimation, float32) against references written here, and
the noise stream's continuity.
"""

import math

from imu_allan import allan_deviation, NoiseModel, simulate
from imu_allan.core.simulation.device_processing import DeviceProcessing
from imu_allan.core.simulation.noise_stream import NoiseStream
from imu_allan.core.simulation.simulate import (
    ar1_scan,
    FLICKER_BANK_CORNERS,
    FLICKER_BANK_WEIGHTS,
    flicker_noise,
)
from imu_allan.core.terms import (
    FLICKER_FLOOR,
    flicker_shape,
    gauss_markov_shape,
    model_avar,
    sampled_flicker_shape,
    sinusoid_shape,
    term_avar,
)
import numpy as np
import pytest


def test_flicker_floor_constant():
    # sqrt(2 ln2 / pi), not 0.644 (thesis MATLAB slip) nor 0.798 (log2 slip, pitfall 4).
    assert FLICKER_FLOOR == pytest.approx(0.664282, abs=1e-6)


@pytest.mark.parametrize('f0_tau,ratio', [(0.1, 0.1744), (0.3, 0.4607), (1, 0.6564),
                                          (3, 0.6633), (10, 0.6642), (100, 0.6643)])
def test_exact_flicker_transient(f0_tau, ratio):
    assert math.sqrt(flicker_shape(f0_tau, 1.0)) == pytest.approx(ratio, abs=1e-4)


def test_read_off_points_of_the_ieee_terms():
    # sigma = Q at sqrt(3), N at 1, K at 3, R at sqrt(2) (IEEE 952 read-off rules).
    adev = lambda term, tau: math.sqrt(term_avar(term, {'value': 2.0}, tau, 1e9))  # noqa: E731
    assert adev('quantization', math.sqrt(3)) == pytest.approx(2.0)
    assert adev('white_noise', 1.0) == pytest.approx(2.0)
    assert adev('rate_random_walk', 3.0) == pytest.approx(2.0)
    assert adev('rate_ramp', math.sqrt(2)) == pytest.approx(2.0)


def test_gauss_markov_peak():
    # ADEV peaks at 1.8926 Tc with 0.4365 q_c sqrt(Tc); q_c^2 = 2 sigma^2 / Tc.
    tc, sigma = 7.0, 0.3
    tau = np.logspace(-1, 3, 20001)
    adev = sigma * np.sqrt(gauss_markov_shape(tau, tc))
    k = int(np.argmax(adev))
    assert tau[k] / tc == pytest.approx(1.8926, rel=1e-3)
    assert adev[k] == pytest.approx(0.4365 * math.sqrt(2 * sigma ** 2 / tc) * math.sqrt(tc),
                                    rel=1e-3)
    # the closed form and its small-tau series agree where they hand over
    assert gauss_markov_shape(0.0099 * tc, tc) == pytest.approx(
        gauss_markov_shape(0.0101 * tc, tc) * 0.0099 / 0.0101, rel=1e-3)


def test_sinusoid_peak_and_nulls():
    f0 = 0.5
    tau = np.linspace(0.05, 1.5, 100001) / f0
    adev = np.sqrt(sinusoid_shape(tau, f0))
    k = int(np.argmax(adev))
    assert tau[k] * f0 == pytest.approx(0.37101, abs=1e-4)
    assert adev[k] == pytest.approx(0.72461, abs=1e-5)
    assert sinusoid_shape(1.0 / f0, f0) == pytest.approx(0.0, abs=1e-20)


#: One model per term, each term alone on one axis.
ONE_TERM = [
    {'white_noise': 1e-3},
    {'quantization': 1e-3},
    {'bias_instability': 1e-4},
    {'rate_random_walk': 1e-5},
    {'rate_ramp': 1e-6},
    {'gauss_markov': {'sigma': 1e-3, 'tau_c': 5.0}},
    {'sinusoid': {'amplitude': 1e-3, 'frequency_hz': 0.2}},
]


@pytest.mark.parametrize('terms', ONE_TERM)
def test_simulated_term_matches_its_analytic_curve(terms):
    # Average of 6 seeds, 1 h at 100 Hz, tau from 0.1 s to T/10. Tolerance: each averaged
    # AVAR must sit within 3 standard errors (from the EDF of 6 pooled runs) plus 3 % for the
    # discrete-vs-continuous shape at short tau; a wrong scale (sqrt 2, 0.664) fails by far.
    model = NoiseModel({'gyro_x': terms})
    runs = [allan_deviation(simulate(model, 360_000, 100.0, seed=s), 100.0) for s in range(6)]
    tau = runs[0].tau
    mean = np.mean([r.avar[:, 0] for r in runs], axis=0)
    edf = np.sum([r.edf[:, 0] for r in runs], axis=0)
    theory = model_avar(model.terms['gyro_x'], tau, 100.0)
    use = (tau >= 0.1) & (theory > 1e-30)
    rel = np.abs(mean[use] / theory[use] - 1.0)
    limit = 3.0 * np.sqrt(2.0 / edf[use]) + 0.03
    assert np.all(rel < limit), (tau[use][rel >= limit], rel[rel >= limit])


def test_flicker_is_one_over_f_not_gauss_markov():
    # A true 1/f series has a flat ADEV over decades; one Gauss-Markov would rise then fall.
    rng = np.random.default_rng(4)
    y = np.mean([flicker_noise(rng, 200_000, 100.0, 1.0) for _ in range(4)], axis=0) * 2.0
    r = allan_deviation(y, 100.0, taus=[0.1, 1.0, 10.0, 100.0])
    assert np.all(np.abs(r.adev[:, 0] / FLICKER_FLOOR - 1.0) < 0.12)


def test_simulate_is_seeded_and_shaped():
    model = NoiseModel.from_dict({'gyro': {'white_noise': 1e-3}, 'accel': {'white_noise': 1e-2}})
    a = simulate(model, 1000, 100.0, seed=42)
    b = simulate(model, 1000, 100.0, seed=42)
    c = simulate(model, 1000, 100.0, seed=43)
    assert a.shape == (1000, 6)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # per-sample std of white noise N at fs is N sqrt(fs) (continuous -> discrete)
    big = simulate(model, 200_000, 100.0, seed=1)
    assert np.std(big[:, 0]) == pytest.approx(1e-3 * 10.0, rel=0.01)


def test_simulate_rejects_bad_arguments():
    model = NoiseModel({'gyro_x': {'white_noise': 1e-3}})
    with pytest.raises(ValueError):
        simulate(model, 10, 0.0)
    with pytest.raises(ValueError):
        simulate(model, -1, 100.0)


# --- the device's own processing (issue 29): window, decimation, float32 ---------------------
# The references below are written here, apart from the code: the window as numpy.convolve
# with a box, correlations as counts of shared internal samples, densities and Allan variances
# as integrals over the internal band.

FI = 1000.0  # the 3DM-GX3-25's internal rate, Hz


def box_decimate(x, window, decimation):
    """Return the device's output for internal samples: box convolution, every decimation-th."""
    return np.convolve(x, np.ones(window) / window, mode='valid')[decimation - 1::decimation]


def shared_fraction(k, window, decimation):
    """Share of the window two outputs k apart have in common (counted, not a formula)."""
    first = set(range(-window + 1, 1))
    second = {i + k * decimation for i in first}
    return len(first & second) / window


def alias_sum(window, decimation):
    """Output over internal white density at 0 Hz: |H|^2 summed over the aliases k f_o."""
    k = np.arange(decimation)[:, None]
    h = np.exp(-2j * np.pi * k * np.arange(window)[None, :] / decimation).mean(axis=1)
    return float(np.sum(np.abs(h) ** 2))


def processed_avar(m, window, decimation, internal_psd, points=2_000_000):
    """
    AVAR at factor m of a process of internal PSD ``internal_psd`` after window and decimation.

    The Allan statistic is a combination of internal samples D apart, so its variance is the
    integral over the internal band of the PSD, the window's |H|^2 and the Allan kernel at the
    output spacing tau0 = D / fi: 4 int_0^{fi/2} S |H|^2 sin^4(pi nu m tau0) /
    (m^2 sin^2(pi nu tau0)) dnu.  Trapezoid on a grid with >= 2000 points per oscillation.
    """
    nu = np.linspace(0.0, FI / 2.0, points + 1)[1:]
    tau0 = decimation / FI
    h = np.sin(np.pi * nu * window / FI) / (window * np.sin(np.pi * nu / FI))
    x = np.pi * nu * tau0
    with np.errstate(invalid='ignore', divide='ignore'):
        kernel = np.nan_to_num(np.sin(m * x) ** 4 / (m * m * np.sin(x) ** 2))
    return 4.0 * np.trapezoid(internal_psd(nu) * h * h * kernel, nu)


def pooled(model, n, rate, seeds, processing, taus=None):
    """Mean AVAR over seeds and the pooled EDF (for a tolerance of 3 standard errors)."""
    runs = [allan_deviation(simulate(model, n, rate, seed=s, processing=processing), rate,
                            taus=taus) for s in seeds]
    return (runs[0].tau, np.mean([r.avar[:, 0] for r in runs], axis=0),
            np.sum([r.edf[:, 0] for r in runs], axis=0))


@pytest.mark.parametrize('window,decimation', [(15, 10), (15, 5), (4, 10), (32, 1), (1, 10),
                                               (20, 10)])
def test_processing_equals_an_independent_convolution(window, decimation):
    # White noise alone on one axis: the internal samples are one draw, so the reference draws
    # the same ones, scaled to the density N / sqrt(alias sum), and convolves.  Equal up to the
    # float32 rounding of values that differ in their last float64 bits: 2 float32 ulps.
    p = DeviceProcessing(FI, window, decimation)
    n, white = 5000, 1e-3
    got = simulate(NoiseModel({'gyro_x': {'white_noise': white}}), n, FI / decimation, seed=3,
                   processing=p)[:, 0]
    c = alias_sum(window, decimation)
    x = white / math.sqrt(c) * math.sqrt(FI) \
        * np.random.default_rng(3).standard_normal(window - 1 + n * decimation)
    want = box_decimate(x, window, decimation).astype(np.float32)
    assert p.alias_gain == pytest.approx(c, rel=1e-12)
    # the same folding in the frequency domain: the output PSD of unit internal white at 0 Hz
    assert p.output_psd(np.array([1e-9]), np.ones_like)[0] == pytest.approx(c, rel=1e-9)
    assert np.array_equal(got.astype(np.float32), got)  # float32 values, as sent
    np.testing.assert_allclose(got, want, rtol=2.4e-7, atol=0.0)


@pytest.mark.parametrize('window,decimation', [(15, 10), (15, 5), (32, 10)])
def test_lag_correlations_of_processed_white_noise(window, decimation):
    # rho_k from the code and from counting shared internal samples, against the sample
    # correlations of 400 000 outputs: their standard error is at most sqrt((1 + 2 sum
    # rho^2) / n) < 0.0025, so 0.01 is 4 standard errors.
    p = DeviceProcessing(FI, window, decimation)
    y = simulate(NoiseModel({'gyro_x': {'white_noise': 1e-3}}), 400_000, FI / decimation,
                 seed=8, processing=p)[:, 0]
    y = y - y.mean()
    for k in range(6):
        counted = shared_fraction(k, window, decimation)
        assert p.lag_correlation(k) == pytest.approx(counted, abs=1e-15)
        measured = np.dot(y[:len(y) - k], y[k:]) / np.dot(y, y)
        assert measured == pytest.approx(counted, abs=0.01), k


def test_processed_white_noise_keeps_its_density_and_shows_the_window():
    # 6 h at 100 Hz (6 seeds), 15 taps, decimation 10.  Long tau: N^2 / tau, the model's
    # continuous-time density (without the alias scaling it would be 10/9 of it).  m = 1: the
    # band-limiting, AVAR(1) = gamma_0 - gamma_1 = 0.4 N^2 / tau0 (the counted rho_1 = 1/3 and
    # sum rho = 5/3).  Every tau: N^2 / tau * white_avar_ratio(m), checked itself against the
    # band integral.  Tolerance: 3 standard errors of the pooled EDF.
    p = DeviceProcessing()
    white = 1e-3
    rho1 = shared_fraction(1, 15, 10)
    assert (1.0 - rho1) / (1.0 + 2.0 * rho1) == pytest.approx(0.4)
    tau, avar, edf = pooled(NoiseModel({'gyro_x': {'white_noise': white}}), 360_000, 100.0,
                            range(6), p)
    m = np.rint(tau * 100.0)
    ratio = avar * tau / white ** 2
    se = np.sqrt(2.0 / edf)
    assert abs(ratio[0] - 0.4) < 3 * se[0]
    assert p.white_avar_ratio(1) == pytest.approx(0.4, rel=1e-12)
    expected = p.white_avar_ratio(m)
    assert np.all(np.abs(ratio / expected - 1.0) < 3 * se), (tau, ratio / expected)
    long = (tau >= 1.0) & (tau <= 30.0)
    level = np.average(ratio[long], weights=edf[long])
    assert abs(level - 1.0) < 0.02 and expected[long].min() > 0.99, level
    c = alias_sum(15, 10)
    for k in (1, 2, 3, 7, 30):
        band = processed_avar(k, 15, 10, lambda nu: np.full(nu.shape, white ** 2 / c))
        assert band / (white ** 2 / (k / 100.0)) == pytest.approx(p.white_avar_ratio(k),
                                                                  rel=1e-4)


@pytest.mark.parametrize('decimation', [10, 1])
def test_processed_flicker_matches_the_band_integral(decimation):
    # Bias instability is generated at the output rate with the spectrum the window and
    # decimation give 1/f noise (output_psd), so its Allan variance must be the band integral
    # of 1/f noise through the window: half the unprocessed value at tau0 for decimation 10,
    # 1 % of it at decimation 1, within 2 % from tau = 0.1 s on.  6 seeds of 200 000
    # samples, tau up to T/100; tolerance 3 standard errors + 2 % (the FFT's finite span).
    p = DeviceProcessing(decimation=decimation)
    rate = p.output_rate_hz
    factors = np.array([1, 2, 5, 10, 20, 100, 200])
    tau, avar, edf = pooled(NoiseModel({'gyro_x': {'bias_instability': 1.0}}), 200_000, rate,
                            range(6), p, taus=factors / rate)
    band = np.array([processed_avar(k, 15, decimation, lambda nu: 1.0 / (2 * np.pi * nu))
                     for k in factors])
    rel = np.abs(avar / band - 1.0)
    assert np.all(rel < 3 * np.sqrt(2.0 / edf) + 0.02), (tau, avar / band)
    unprocessed = sampled_flicker_shape(tau, rate)
    assert band[0] / unprocessed[0] < (0.55 if decimation == 10 else 0.02)
    assert np.all(np.abs(band / unprocessed - 1.0)[tau >= 0.1] < 0.02)


def ar1_avar(lam, m):
    """
    Exact AVAR per unit variance of a discrete AR(1) with phi = exp(-lam), at factor m.

    m^2 AVAR = m coth(lam/2) - (1 - e^-x)(3 - e^-x) / (4 sinh^2(lam/2)), x = m lam, from
    AVAR = (4 V(m) - V(2m)) / (2 m^2), V the variance of a sum of m samples; for x < 1e-3 its
    series lam / (3m) + 2 m lam / 3 - m^2 lam^2 / 2, where the closed form cancels.
    """
    m = np.asarray(m, dtype=float)
    x = m * lam
    with np.errstate(all='ignore'):
        closed = (m / np.tanh(lam / 2) + np.expm1(-x) * (3 - np.exp(-x))
                  / (4 * np.sinh(lam / 2) ** 2)) / m ** 2
    return np.where(x < 1e-3, lam / (3 * m) + 2 * m * lam / 3 - m * m * lam * lam / 2, closed)


def sum_variance(n, phi):
    """Variance of a sum of n AR(1) samples (unit variance): sum over lags |k| < n."""
    lags = np.abs(np.arange(-n + 1, n))
    return np.sum((n - lags) * phi ** lags)


def test_ar1_avar_reference_against_direct_sums():
    for lam in (3.0, 0.3, 0.01, 1e-4):
        phi = math.exp(-lam)
        for m in (1, 2, 3, 10, 100, 1000):
            direct = (4 * sum_variance(m, phi) - sum_variance(2 * m, phi)) / (2 * m * m)
            assert ar1_avar(lam, m) == pytest.approx(direct, rel=1e-6), (lam, m)


def test_flicker_bank_is_one_over_f_over_eight_decades():
    # The stream's flicker: the bank's exact Allan variance (sum of its sections') against the
    # sampled 1/f curve, from m = 1 to 1e8 samples: the stated 1.6 % at m = 2, 0.8 % from 3.
    m = np.unique(np.round(np.logspace(0, 8, 400)))
    lam = 2 * np.pi * FLICKER_BANK_CORNERS
    variance = FLICKER_BANK_WEIGHTS * math.log(10.0) / (2 * np.pi)
    bank = sum(v * ar1_avar(k, m) for v, k in zip(variance, lam))
    rel = np.abs(bank / sampled_flicker_shape(m, 1.0) - 1.0)
    assert rel.max() < 0.016 and rel[m >= 3].max() < 0.008, (m[np.argmax(rel)], rel.max())


@pytest.mark.parametrize('terms', ONE_TERM)
def test_a_stream_does_not_depend_on_its_blocks(terms):
    # One term on one axis: every draw of a block follows the previous block's, so a stream
    # cut into blocks of 37, 1, 500 and 62 samples is the one of 600 samples, exactly: no term
    # restarts at a block boundary, and the window reaches back into the previous block.
    model = NoiseModel({'gyro_x': terms})
    whole = NoiseStream(model, DeviceProcessing(), seed=4).take(600)
    stream = NoiseStream(model, DeviceProcessing(), seed=4)
    parts = np.concatenate([stream.take(n) for n in (37, 1, 500, 62)])
    np.testing.assert_array_equal(parts, whole)
    assert np.array_equal(whole.astype(np.float32), whole) and np.ptp(whole) > 0


def test_stream_processing_changes_and_refusals():
    model = NoiseModel({'gyro_x': {'white_noise': 1e-3}})
    stream = NoiseStream(model, DeviceProcessing(), seed=1, history=32)
    assert stream.take(100).shape == (100, 1)
    stream.processing = DeviceProcessing(window=32, decimation=2)
    assert stream.take(250).shape == (250, 1)
    with pytest.raises(ValueError, match='exceeds'):
        NoiseStream(model, DeviceProcessing(), seed=1).processing = DeviceProcessing(window=16)
    with pytest.raises(ValueError, match='internal rate'):
        stream.processing = DeviceProcessing(internal_rate_hz=500.0)


def test_device_processing_refuses_what_is_no_processing():
    for bad in ({'window': 0}, {'decimation': 2.5}, {'internal_rate_hz': -1.0},
                {'window': True}):
        with pytest.raises(ValueError):
            DeviceProcessing(**bad)
    model = NoiseModel({'gyro_x': {'white_noise': 1e-3}})
    with pytest.raises(ValueError, match='decimation 10 = 100 Hz'):
        simulate(model, 10, 200.0, processing=DeviceProcessing())
    assert DeviceProcessing().window_s == pytest.approx(0.015)
    assert simulate(model, 0, 100.0, processing=DeviceProcessing()).shape == (0, 1)


def test_ar1_scan_is_the_recursion():
    # The stream's flicker sections: the doubling scan against the recursion written out.
    rng = np.random.default_rng(6)
    phi = np.array([0.0, 0.04, 0.5, 0.999, 1.0 - 1e-9])
    drive, last = rng.standard_normal((300, phi.size)), rng.standard_normal(phi.size)
    want, x = np.empty_like(drive), last.copy()
    for i, row in enumerate(drive):
        x = phi * x + row
        want[i] = x
    np.testing.assert_allclose(ar1_scan(drive, phi, last), want, rtol=1e-12, atol=1e-12)
