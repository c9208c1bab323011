"""
The sensor's processing measured from its samples (core/sensor/: measure.py, spectrum.py).

Checked on the two real ADIS16405 records (against quantities the tests compute themselves:
the full-record repeat fraction, a variogram estimate of rho_1, chunked least-squares sine
fits, a hump's excess from scipy's Welch spectrum) and on generators written here, without
package code: white noise at 1 kHz through an M-tap moving average, decimated (rho_k =
max(0, M - D k) / M exactly), rounded to an LSB, with sinusoids, flicker and random walk.
"""

import json
import math

from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.sensor.measure import MAX_EXAMINED, measure_sensor, SensorAccumulator
import numpy as np
import pytest

G0 = 9.80665


# ---------------------------------------------------------------- generators (no package code)

def moving_average(rng, n, taps, factor, sigma=1.0):
    """
    White noise at the internal rate through a ``taps``-tap moving average, every ``factor``-th.

    Per-sample variance sigma^2; rho_k = max(0, taps - factor k) / taps exactly.
    """
    w = rng.standard_normal(factor * n + taps)
    c = np.concatenate([[0.0], np.cumsum(w)])
    return (c[taps:] - c[:-taps])[::factor][:n] * (sigma / math.sqrt(taps))


def ma_truth(taps, factor, sigma=1.0):
    """(R_0..R_K, S, D) of :func:`moving_average`, per sample."""
    r = np.array([(taps - factor * k) / taps for k in range(-(-taps // factor))]) * sigma ** 2
    lags = np.arange(r.size)
    return r, r[0] + 2.0 * r[1:].sum(), 2.0 * (lags * r).sum()


def flicker(rng, n, rate_hz, b):
    """1/f noise, two-sided PSD b^2 / (2 pi f) from 1/(8 T) up, by shaping white noise."""
    m = 8 * n
    f = np.fft.rfftfreq(m, 1.0 / rate_hz)
    psd = np.zeros(f.size)
    psd[1:] = b * b / (2.0 * np.pi * f[1:])
    z = (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)) * np.sqrt(
        psd * m * rate_hz / 2.0)
    return np.fft.irfft(z, m)[:n]


def random_walk(rng, n, rate_hz, k):
    """Random walk of strength k (two-sided PSD k^2 / (2 pi f)^2)."""
    return np.cumsum(rng.standard_normal(n)) * k / math.sqrt(rate_hz)


# ---------------------------------------------------------------- the real ADIS16405 records

@pytest.fixture(scope='module')
def adis(shared_data):
    """Both runs in SI (gyro rad/s, accel m/s^2) and their reports."""
    out = {}
    for run in (2, 3):
        d = np.load(shared_data / 'adis16405' / f'adis_16405_run{run}.npz')
        data = np.hstack([d['gyro_deg_s'] * (math.pi / 180.0), d['accel_g'] * G0])
        out[run] = (data, measure_sensor(data, float(d['rate_hz'])))
    return out


@pytest.mark.parametrize('run', [2, 3])
def test_adis_grid_repeats_and_quantization(adis, run):
    """LSB 0.05 deg/s and 3.33 mg exactly; repeats as in the whole record; fine rounding."""
    data, report = adis[run]
    for a, (name, ax) in enumerate(report.axes.items()):
        x = data[:, a]
        full = float(np.mean(x[1:] == x[:-1]))   # the whole record, counted here
        # the report examines 2^18 of the 10^6 samples, in 32 spread segments: a sample
        assert abs(ax.repeated_fraction - full) < 0.01, name
        assert ax.off_grid_fraction == 0.0
        assert ax.quantization == 'fine'
        assert ax.quantization_density == pytest.approx(ax.resolution / math.sqrt(1200.0))
        if name.startswith('gyro'):
            assert ax.resolution == pytest.approx(0.05 * math.pi / 180.0, rel=1e-9)
            assert 0.03 < ax.repeated_fraction < 0.05
            assert 60 <= ax.distinct_values <= 80
            assert 5.0 < ax.noise_to_lsb < 9.0
        else:
            assert ax.resolution / G0 == pytest.approx(3.33e-3, rel=1e-6)
            assert 0.2 < ax.repeated_fraction < 0.4
            assert 12 <= ax.distinct_values <= 22
            assert 0.6 < ax.noise_to_lsb < 1.5


@pytest.mark.parametrize('run', [2, 3])
def test_adis_filter(adis, run):
    """
    rho_1 0.12-0.21, nothing beyond lag 1; gyro_x/y's rho_1 as a variogram reads it.

    The variogram V(k) = E[(x_{t+k} - x_t)^2] / 2 is R_0 - R_k plus the slow noise's share,
    flat over a few lags, so rho_1 = 1 - V(1) / mean V(3..8) when R_k = 0 beyond lag 1; on
    gyro_x/y (no line, no hump to bend it) it agrees to 0.01 (measured: within 0.0021).
    """
    data, report = adis[run]
    for a, (name, ax) in enumerate(report.axes.items()):
        assert 0.12 < ax.lag_correlation[0] < 0.21, name
        assert ax.filter_length == 1, name
        assert ax.lag_correlation_se[0] < 0.01
        assert 30.0 < ax.bandwidth_hz < 45.0       # fs/2 = 50 Hz for white samples
        if name in ('gyro_x', 'gyro_y'):
            x = data[:, a]
            v = [np.mean((x[k:] - x[:-k]) ** 2) / 2.0 for k in range(1, 9)]
            assert ax.lag_correlation[0] == pytest.approx(1.0 - v[0] / np.mean(v[2:]),
                                                          abs=0.01)


def _chunked_sine_amplitude(x, rate_hz, f0, chunk=8192):
    """
    Root mean square over 82-s chunks of the least-squares sine amplitude near f0.

    Per chunk and trial frequency (f0 +- 0.01 Hz in 0.0005-Hz steps) the chunk, less its
    mean and slope, is fitted by a cosine and a sine (normal equations, 2 x 2); the best
    frequency's amplitude counts.
    """
    t = np.arange(chunk) / rate_hz
    tc = t - t.mean()
    chunks = x[:x.size // chunk * chunk].reshape(-1, chunk)
    chunks = chunks - chunks.mean(axis=1, keepdims=True)
    chunks -= np.outer(chunks @ tc / (tc @ tc), tc)
    best = np.zeros(chunks.shape[0])
    for f in np.arange(f0 - 0.01, f0 + 0.01, 0.0005):
        basis = np.column_stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)])
        basis -= basis.mean(axis=0)
        basis -= np.outer(tc, tc @ basis / (tc @ tc))
        coef = np.linalg.solve(basis.T @ basis, basis.T @ chunks.T)
        best = np.maximum(best, np.sum(coef ** 2, axis=0))
    return math.sqrt(best.mean())


@pytest.mark.parametrize('run, line_hz', [(2, 0.567), (3, 0.540)])
def test_adis_lines_and_humps(adis, run, line_hz):
    """
    The accelerometers' line, its amplitude as least squares fits it; gyro_z's resonance.

    The line wanders (0.565-0.569 Hz in run 2) and its amplitude with it, so the independent
    fit is per 82-s chunk, frequency scanned +-0.01 Hz, and the root mean square of the chunk
    amplitudes is compared: within 10 % (measured 0.2-2.5 %).  gyro_z's hump against its own
    Welch spectrum (scipy) over 14-35 Hz minus gyro_x's shape scaled to it below 14 Hz: within
    15 % (measured 1.5-1.6 %).
    """
    from scipy.signal import welch
    data, report = adis[run]
    for a, name in enumerate(('accel_x', 'accel_y', 'accel_z'), start=3):
        lines = report.axes[name].lines
        near = [line for line in lines if abs(line.frequency_hz - line_hz) < 0.005]
        assert len(near) == 1, (name, lines)
        line = near[0]
        assert line.false_alarm_probability < 1e-12
        assert line.amplitude == pytest.approx(
            _chunked_sine_amplitude(data[:, a], 100.0, line.frequency_hz), rel=0.10)
    for name in ('gyro_x', 'gyro_y'):
        assert report.axes[name].lines == [] and report.axes[name].humps == [], name
    humps = report.axes['gyro_z'].humps
    main = max(humps, key=lambda h: h.excess_variance)
    lo, hi = main.frequency_range_hz
    assert lo < 18.0 and hi > 22.0 and 18.5 < main.peak_hz < 21.0
    assert main.peak_ratio > 5.0
    f, px = welch(data[:, 0], fs=100.0, nperseg=8192)
    _, pz = welch(data[:, 2], fs=100.0, nperseg=8192)
    base, band = (f > 2) & (f < 14), (f > 14) & (f < 35)
    scale = np.median(pz[base] / px[base])
    excess = np.sum(pz[band] - scale * px[band]) * (f[1] - f[0])
    assert sum(h.excess_variance for h in humps) == pytest.approx(excess, rel=0.15)


# ---------------------------------------------------------------- the filter, exactly known

@pytest.mark.parametrize('taps, factor, rate_hz', [(25, 10, 100.0), (40, 5, 200.0),
                                                   (10, 10, 100.0)])
def test_moving_average_filter(taps, factor, rate_hz):
    """
    rho_k, filter_length, bandwidth and moment of a decimated moving average, exactly known.

    2^18 samples: rho_k within 5 of its reported standard errors (+0.001), each under 0.005
    (measured: largest deviation 0.0006); bandwidth and moment within 1 % (measured 0.09 %).
    """
    rng = np.random.default_rng(taps * 100 + factor)
    x = moving_average(rng, MAX_EXAMINED, taps, factor, sigma=0.01)
    ax = measure_sensor(x, rate_hz, ['gyro_x']).axes['gyro_x']
    r, s, d = ma_truth(taps, factor, sigma=0.01)
    k = r.size - 1
    assert ax.filter_length == k
    exact = np.zeros(8)
    exact[:k] = r[1:] / r[0]
    got, se = np.array(ax.lag_correlation), np.array(ax.lag_correlation_se)
    assert np.all(se < 0.005)
    assert np.all(np.abs(got - exact) < 5.0 * se + 0.001), (got, exact, se)
    assert ax.bandwidth_hz == pytest.approx(r[0] / s * rate_hz / 2.0, rel=0.01)
    assert ax.filter_moment == pytest.approx(d / s, rel=0.01, abs=0.01)
    assert ax.white_variance == pytest.approx(s, rel=0.01)
    assert ax.resolution is None and ax.lines == [] and ax.humps == []


@pytest.mark.parametrize('seed', range(4))
def test_long_window_under_flicker_and_a_line_is_a_filter_not_a_hump(seed):
    """
    A 27-tap average at 1 kHz decimated by 5 (200 Hz), under flicker and an aliased line.

    The main lobe spans 0-37 Hz; with flicker strong at the fit's low edge (fs / 100, here 10x
    the white PSD at 0.2 Hz, as in a 1-h realistic calibration record that lost its white
    noise) a two-lag fit took the whole lobe for a hump and its "white part" was the floor
    above it (S off by 0.17-5.7x over these seeds).  Now: all 5 lags, S within 8 % of
    the truth (the taps' fold plus the rounding's q^2 / 12; measured 0.96-1.04), the moment
    within 3 % (measured 1 %), the line at its alias 13.2 Hz, no hump.
    """
    rng = np.random.default_rng(seed)
    n, taps, factor, sigma, q = MAX_EXAMINED, 27, 5, 0.01, 0.0084
    w = rng.standard_normal(factor * n + taps)
    w += 0.35 * math.sqrt(taps) * np.sin(2 * np.pi * 386.8 * np.arange(w.size) / 1000.0 + 0.4)
    c = np.concatenate([[0.0], np.cumsum(w)])
    x = (c[taps:] - c[:-taps])[::factor][:n] * (sigma / math.sqrt(taps))
    x = np.round((x + flicker(rng, n, 200.0, 0.01)) / q) * q
    ax = measure_sensor(x, 200.0, ['gyro_x']).axes['gyro_x']
    r, s, d = ma_truth(taps, factor, sigma)
    total = s + q * q / 12.0
    assert ax.filter_length == r.size - 1 == 5
    assert ax.white_variance == pytest.approx(total, rel=0.08)
    assert ax.filter_moment == pytest.approx(d / total, rel=0.03)
    assert [round(line.frequency_hz, 1) for line in ax.lines] == [13.2]
    assert ax.humps == []


def test_allan_variance_of_the_white_part():
    """
    AVAR = S tau0 / tau - 1.5 D tau0^2 / tau^2 for m >= filter_length (allan_deviation).

    Derivation (docs/method.md): for m >= K the m-sample mean has variance (S - D / m) / m
    and adjacent means covary by D / (2 m^2).  A 40-tap moving average at 1 kHz decimated to
    200 Hz (K = 7, D / S = 2.6) is where the D term is large: at m = 7 it halves AVAR.  The
    estimate agrees within its 68 % interval widened 3x (about 1 % here) at every m, where
    S / m alone is 2.3x off at m = 7; the measured S, D give the same curve within 1 %.
    """
    rate_hz, taps, factor = 200.0, 40, 5
    x = moving_average(np.random.default_rng(11), 2 ** 20, taps, factor)
    r, s, d = ma_truth(taps, factor)
    m = np.array([7, 8, 10, 14, 20, 30, 50, 80])
    res = allan_deviation(x[:, None], rate_hz, taus=m / rate_hz)
    theory = s / res.m - 1.5 * d / res.m ** 2
    ratio = res.avar[:, 0] / theory
    half_width = 3.0 * (res.ci_high[:, 0] ** 2 - res.ci_low[:, 0] ** 2) / (
        2.0 * res.avar[:, 0])
    assert np.all(np.abs(ratio - 1.0) < half_width), (ratio, half_width)
    assert (s / 7.0) / theory[0] > 2.0
    ax = measure_sensor(x, rate_hz, ['gyro_x']).axes['gyro_x']
    assert ax.filter_length == 7
    np.testing.assert_allclose(ax.white_avar(res.tau), theory, rtol=0.01)


@pytest.mark.parametrize('lsb_sigmas, regime', [(0.2, 'fine'), (1.0, 'fine'),
                                                (3.0, 'coarse')])
def test_rounding_to_an_lsb(lsb_sigmas, regime):
    """
    The LSB found exactly from 0.2 to 3 noise sigmas, with an offset; its regime; its noise.

    In the fine regime rounding adds white noise q^2 / 12, so rho_1 becomes R_1 / (R_0 +
    q^2 / 12) (within 5 standard errors + 0.002) and noise_to_lsb reads sigma / q (3 %).
    """
    rng = np.random.default_rng(int(lsb_sigmas * 10))
    sigma, q = 0.02, 0.02 * lsb_sigmas
    x = 9.81 + moving_average(rng, 2 ** 18, 25, 10, sigma)
    x = q * np.round(x / q)
    ax = measure_sensor(x, 100.0, ['accel_z']).axes['accel_z']
    assert ax.resolution == pytest.approx(q, rel=1e-9)
    assert ax.quantization == regime
    assert ax.off_grid_fraction == 0.0
    if regime == 'fine':
        assert ax.quantization_density == pytest.approx(q / math.sqrt(12.0 * 100.0))
        assert ax.noise_to_lsb == pytest.approx(1.0 / lsb_sigmas, rel=0.03)
        expected = 0.6 / (1.0 + lsb_sigmas ** 2 / 12.0)
        assert abs(ax.lag_correlation[0] - expected) < 5 * ax.lag_correlation_se[0] + 0.002
    else:
        assert ax.quantization_density is None
        assert ax.noise_to_lsb < 0.5
        assert ax.repeated_fraction > 0.5     # mostly one level, held


def test_sample_and_hold():
    """Float samples each held twice: half the pairs repeat, rho_1 = 1/2, no grid."""
    rng = np.random.default_rng(5)
    x = np.repeat(rng.standard_normal(2 ** 17) * 0.01, 2)
    ax = measure_sensor(x, 100.0, ['gyro_x']).axes['gyro_x']
    assert ax.resolution is None
    assert ax.repeated_fraction == pytest.approx(0.5, abs=0.01)
    assert ax.filter_length == 1
    assert ax.lag_correlation[0] == pytest.approx(0.5, abs=0.01)


# ---------------------------------------------------------------- lines

def test_lines_found_with_their_amplitude_and_alias():
    """
    Two lines at 100 Hz, and one at 130 Hz at the 1 kHz internal rate, seen at its alias 30 Hz.

    Frequencies within 0.3 bin (0.0037 Hz; over 12 seeds the 7.3-Hz line's sd is 0.0002 Hz,
    the weak 1.2-Hz one's 0.0015 Hz: its power is 1.3 times the noise in its bin).  Amplitudes
    from the main lobe's excess over the median background: over 12 seeds the 7.3-Hz line
    reads 0.201 +- 0.0065 (tolerance 10 %, 3 sd), the weak one 0.056 +- 0.0045 (25 %), the
    alias (130 Hz through the 25-tap average: A |H(130 Hz)| = 0.070 A, power 5000 times the
    noise in its bin) within 3 %.
    """
    rng = np.random.default_rng(21)
    n, taps, factor = 2 ** 19, 25, 10
    t_fast = np.arange(factor * n + taps) / 1000.0
    w = rng.standard_normal(t_fast.size) + 3.0 * np.sin(2 * np.pi * 130.0 * t_fast + 0.3)
    c = np.concatenate([[0.0], np.cumsum(w)])
    x = (c[taps:] - c[:-taps])[::factor][:n] / math.sqrt(taps)
    t = np.arange(n) / 100.0
    x = x + 0.2 * np.sin(2 * np.pi * 7.3137 * t + 1.0) + 0.05 * np.sin(2 * np.pi * 1.234 * t)
    ax = measure_sensor(x, 100.0, ['gyro_x']).axes['gyro_x']
    gain = abs(math.sin(math.pi * 130.0 * taps / 1000.0)
               / (taps * math.sin(math.pi * 130.0 / 1000.0))) * math.sqrt(taps)
    expected = [(1.234, 0.05, 0.25), (7.3137, 0.2, 0.10), (30.0, 3.0 * gain, 0.03)]
    assert len(ax.lines) == 3, ax.lines
    for line, (f0, amp, tol) in zip(sorted(ax.lines, key=lambda li: li.frequency_hz),
                                    expected):
        assert line.frequency_hz == pytest.approx(f0, abs=0.3 * 100.0 / 8192)
        assert line.amplitude == pytest.approx(amp, rel=tol)
        assert line.snr > 1 and line.false_alarm_probability < 1e-3
    assert ax.filter_length == 2     # the lines are left out of the white part


def _null_record(kind, rng, n):
    """Return a line-free record: band-limited white noise, or white + flicker + walk."""
    if kind == 'band-limited':
        return moving_average(rng, n, 25, 10)
    # flicker and random walk each 20 % of the white level at 1 Hz (two-sided densities;
    # about what the thesis 3DM-GX3-25 accelerometer shows)
    white = 1.0 / 100.0
    return (rng.standard_normal(n) + flicker(rng, n, 100.0, math.sqrt(0.2 * white * 2 * math.pi))
            + random_walk(rng, n, 100.0, math.sqrt(0.2 * white) * 2 * math.pi))


@pytest.mark.parametrize('kind', ['band-limited', 'white+flicker+random walk'])
def test_false_alarm_rate(kind):
    """
    At most 2 % of 240 line-free records (6 axes x 40, 11 min at 100 Hz each) show a line.

    The test is set for 0.5 % per axis (Bonferroni over the ~4000 bins searched); measured on
    1000 records each of 22 min: 0.1 % (white), 0.6 % (band-limited), 0.4 % (white + flicker
    + random walk), 0.6 % (band-limited, rounded to sigma / 2); here 1 and 0 of 240.  No
    record shows a hump (measured: none of those 4000).
    """
    rng = np.random.default_rng(2024)
    n, records, with_line, with_hump = 2 ** 16, 0, 0, 0
    for _ in range(40):
        data = np.column_stack([_null_record(kind, rng, n) for _ in range(6)])
        report = measure_sensor(data, 100.0)
        for ax in report.axes.values():
            records += 1
            with_line += bool(ax.lines)
            with_hump += bool(ax.humps)
    assert records == 240
    assert with_line / records <= 0.02
    assert with_hump / records <= 0.02


# ---------------------------------------------------------------- slow noise does not bias rho

def test_slow_noise_does_not_bias_the_lags():
    """
    Flicker and random walk at 20 % of the white level at 1 Hz leave rho_k in place.

    The white part's rho_k stay within 4 standard errors + 0.003 of the moving average's
    (measured shift: 0.002); the plain sample autocorrelation of the same data is off by more
    than 0.05 at every lag.  And on the moving average alone, subtracting a 1-s moving
    average first (the usual cure) moves rho_1 by -(1 - rho_1) S / (101 R_0) = -0.010: the
    spectral fit has no such bias.
    """
    rng = np.random.default_rng(77)
    n = 2 ** 19
    ma = moving_average(rng, n, 25, 10)
    s = 2.6                                     # S of the moving average (per sample)
    white = s / 100.0                           # its two-sided density at low frequency
    x = (ma + flicker(rng, n, 100.0, math.sqrt(0.2 * white * 2 * math.pi))
         + random_walk(rng, n, 100.0, math.sqrt(0.2 * white) * 2 * math.pi))
    ax = measure_sensor(x, 100.0, ['accel_x']).axes['accel_x']
    assert ax.filter_length == 2
    for k, exact in ((1, 0.6), (2, 0.2)):
        assert abs(ax.lag_correlation[k - 1] - exact) < 4 * ax.lag_correlation_se[k - 1] + 0.003
    y = x - x.mean()
    plain = [np.dot(y[k:], y[:-k]) / np.dot(y, y) for k in (1, 2, 3)]
    assert all(abs(p - e) > 0.05 for p, e in zip(plain, (0.6, 0.2, 0.0)))
    hp = ma[50:-50] - np.convolve(ma, np.ones(101) / 101, mode='same')[50:-50]
    rho1 = np.dot(hp[1:], hp[:-1]) / np.dot(hp, hp)
    assert rho1 == pytest.approx(0.6 - 0.4 * s / 101, abs=0.002)
    ours = measure_sensor(ma, 100.0, ['accel_x']).axes['accel_x']
    assert abs(ours.lag_correlation[0] - 0.6) < 0.002


# ---------------------------------------------------------------- odd input

def test_float32_output_has_no_grid():
    """Float32 samples (as the 3DM-GX3-25 sends): no LSB, near zero or at 1 g."""
    rng = np.random.default_rng(3)
    data = np.column_stack([rng.standard_normal(2 ** 16) * 0.01,
                            9.80665 + rng.standard_normal(2 ** 16) * 0.01,
                            9.80665 + rng.standard_normal(2 ** 16) * 1e-4]).astype(np.float32)
    report = measure_sensor(data, 100.0, ['gyro_x', 'accel_z', 'accel_y'])
    for ax in report.axes.values():
        assert ax.resolution is None and ax.quantization is None
        assert ax.filter_length == 0
    json.dumps(report.to_json(), allow_nan=False)


@pytest.mark.parametrize('n', [0, 1, 2, 10, 100, 255, 256, 1000, 40000])
def test_degenerate_records_give_a_report(n):
    """Short, constant, one-axis and NaN-holding records: a report, never an exception."""
    rng = np.random.default_rng(n)
    cases = [np.zeros((n, 6)), np.full(n, 3.0), rng.standard_normal((n, 1)),
             np.round(rng.standard_normal((n, 2)) * 3) / 3]
    if n > 2:
        holed = rng.standard_normal((n, 2))
        holed[n // 3, 0] = np.nan
        holed[:, 1] = np.inf
        cases.append(holed)
    for data in cases:
        report = measure_sensor(data, 100.0)
        text = json.dumps(report.to_json(), allow_nan=False)
        assert report.n_samples == n and text


def test_constant_record():
    """All samples equal: no grid to find, every pair repeats, no noise to measure."""
    const = measure_sensor(np.full((5000, 1), 2.5), 100.0, ['gyro_x']).axes['gyro_x']
    assert const.resolution is None and const.repeated_fraction == 1.0
    assert const.distinct_values == 1 and const.lag_correlation is None
    assert const.lines == [] and const.humps == []


def test_rate_must_be_positive():
    """A rate that is not a positive number is a programming error: ValueError."""
    for rate in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError):
            measure_sensor(np.zeros((10, 1)), rate)
        with pytest.raises(ValueError):
            SensorAccumulator(rate, ['gyro_x'])


# ---------------------------------------------------------------- streaming

def _flatten(obj, prefix=''):
    if isinstance(obj, dict):
        for key, value in obj.items():
            yield from _flatten(value, f'{prefix}.{key}')
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            yield from _flatten(value, f'{prefix}[{i}]')
    else:
        yield prefix, obj


def _assert_reports_equal(a, b, rtol):
    fa, fb = dict(_flatten(a.to_json())), dict(_flatten(b.to_json()))
    assert fa.keys() == fb.keys()
    for key in fa:
        if isinstance(fa[key], float) and isinstance(fb[key], float):
            assert fa[key] == pytest.approx(fb[key], rel=rtol, abs=1e-300), key
        else:
            assert fa[key] == fb[key], key


@pytest.mark.parametrize('n', [20000, 250000])
def test_accumulator_equals_measure_sensor(n):
    """
    Blocks of random sizes give measure_sensor's report for the same samples (rel 1e-9).

    Up to MAX_EXAMINED samples both take the same segments and values; only the order of the
    Welch sums differs, so they agree to rounding (1e-9 leaves room for it).  Short records
    (20000 < 4 L) are measured from the kept samples.
    """
    rng = np.random.default_rng(n)
    q = 0.005
    data = np.column_stack([
        q * np.round(moving_average(rng, n, 25, 10, 0.02) / q),
        moving_average(rng, n, 30, 10, 0.03) + 0.01 * np.sin(0.1 * np.arange(n))])
    acc = SensorAccumulator(100.0, ['gyro_x', 'accel_x'])
    start = 0
    while start < n:
        size = int(rng.integers(1, 5000))
        acc.update(data[start:start + size])
        start += size
    _assert_reports_equal(acc.report(), measure_sensor(data, 100.0, ['gyro_x', 'accel_x']),
                          rtol=1e-9)
    if n > 4 * acc.length:     # memory stays bounded: no kept samples beyond half a segment
        assert acc._head == [] and acc._tail.shape[0] < acc.length


def test_accumulator_on_a_long_record():
    """Beyond MAX_EXAMINED the accumulator sees every sample: same answers within error."""
    rng = np.random.default_rng(8)
    n = 2 ** 20 + 12345
    q = 0.004
    x = q * np.round((moving_average(rng, n, 25, 10, 0.02)
                      + 0.004 * np.sin(2 * np.pi * 3.3 * np.arange(n) / 100.0)) / q)
    acc = SensorAccumulator(100.0, ['gyro_x'])
    for start in range(0, n, 7777):
        acc.update(x[start:start + 7777, None])
    a = acc.report().axes['gyro_x']
    b = measure_sensor(x, 100.0, ['gyro_x']).axes['gyro_x']
    assert a.n_examined == n and b.n_examined == MAX_EXAMINED
    assert a.resolution == pytest.approx(b.resolution, rel=1e-12)
    assert a.filter_length == b.filter_length == 2
    assert abs(a.lag_correlation[0] - b.lag_correlation[0]) < 4 * b.lag_correlation_se[0]
    assert [round(li.frequency_hz, 2) for li in a.lines] == [3.3]
    assert [round(li.frequency_hz, 2) for li in b.lines] == [3.3]
    assert a.repeated_fraction == pytest.approx(b.repeated_fraction, abs=0.005)


def test_json_is_strict_and_says_its_units():
    """to_json: no NaN, units named, lists of lines and humps."""
    rng = np.random.default_rng(1)
    x = np.round(moving_average(rng, 2 ** 16, 25, 10) * 20) / 20
    out = measure_sensor(np.column_stack([x, x]), 100.0, ['gyro_x', 'accel_x']).to_json()
    json.dumps(out, allow_nan=False)
    assert out['axes']['gyro_x']['unit'] == 'rad/s'
    assert out['axes']['accel_x']['unit'] == 'm/s^2'
    assert 'continuous time' in out['units']['quantization_density']
    assert 'per sample' in out['units']['white_variance']
    assert out['axes']['gyro_x']['resolution'] == pytest.approx(0.05)
