"""Wavelet / median denoising: block streaming == batch, latency, effect on Allan deviation."""

from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.denoise import block_geometry, BlockDenoiser, denoise, sure_threshold
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
import numpy as np
import pytest

RATE = 100.0


def _stream(denoiser, data, seed):
    rng = np.random.default_rng(seed)
    outs, i = [], 0
    while i < data.shape[0]:
        n = int(rng.integers(1, 800))
        outs.append(denoiser.push(data[i:i + n]))
        i += n
    return np.concatenate(outs)


@pytest.fixture(scope='module')
def signal():
    """Noise plus a random walk and a sine: something to keep and something to remove."""
    rng = np.random.default_rng(0)
    n = 12000
    return (rng.standard_normal((n, 3))
            + np.cumsum(0.02 * rng.standard_normal((n, 3)), axis=0)
            + np.sin(np.arange(n) / 50.0)[:, None])


@pytest.mark.parametrize('wavelet, level, rule, mode', [
    ('sym8', 4, 'universal', 'soft'), ('sym8', 6, 'minimax', 'hard'),
    ('db4', 5, 'universal', 'hard'), ('haar', 3, 'minimax', 'soft')])
def test_block_output_equals_whole_record_batch(signal, wavelet, level, rule, mode):
    """
    With a given noise level, every streamed sample equals the batch on the whole record.

    Both run the same float operations on the same coefficients, so the tolerance is 1e-12
    (rounding only); a wrong block alignment or margin gives errors of order 0.1.
    """
    opts = {'wavelet': wavelet, 'level': level, 'rule': rule, 'mode': mode, 'sigma': 1.0,
            'n_ref': 4096}
    full = denoise(signal, RATE, **opts)
    bd = BlockDenoiser(RATE, 3, **opts)
    out = _stream(bd, signal, seed=level)
    # Bounded latency: everything older than latency_samples has been output.
    assert out.shape[0] >= signal.shape[0] - bd.latency_samples
    np.testing.assert_allclose(out, full[:out.shape[0]], rtol=0, atol=1e-12)
    tail = bd.flush()
    assert out.shape[0] + tail.shape[0] == signal.shape[0]


def test_block_with_mad_noise_is_the_batch_on_each_block(signal):
    """Data-driven thresholds: each output hop equals denoise() of its own block."""
    bd = BlockDenoiser(RATE, 3, wavelet='sym8', level=4)
    out = _stream(bd, signal, seed=9)
    margin, hop = bd.margin, bd.hop
    for first in (0, hop * 7, hop * 100):
        lo = max(0, first - margin)
        block = signal[lo:first + hop + margin]
        want = denoise(block, RATE, wavelet='sym8', level=4, n_ref=bd.block_len)
        np.testing.assert_allclose(out[first:first + hop], want[first - lo:first - lo + hop],
                                   rtol=0, atol=1e-12)


def test_median_block_equals_batch(signal):
    """The median filter streams exactly (window 21: margin 11 samples)."""
    full = denoise(signal, method='median', median_window=21)
    bd = BlockDenoiser(RATE, 3, method='median', median_window=21)
    out = _stream(bd, signal, seed=4)
    np.testing.assert_array_equal(out, full[:out.shape[0]])


def test_latency_table_values():
    """The stated latencies: sym8 level 4 at 100 Hz = 240 + 16 samples; level 12 = 61440 + ..."""
    assert block_geometry('wavelet', 'sym8', 4, rate_hz=100.0) == (240, 16, 16)
    margin, hop, align = block_geometry('wavelet', 'sym8', 12, rate_hz=100.0)
    assert (margin, align) == (61440, 4096) and hop == 4096
    assert BlockDenoiser(100.0, 6).latency_s == pytest.approx(2.55)  # the shipped default


def test_sure_threshold_and_options():
    """SURE picks a threshold near the signal/noise split; bad options are refused."""
    rng = np.random.default_rng(1)
    x = np.concatenate([rng.standard_normal(900), 20 + rng.standard_normal(100)])
    assert 1.0 < sure_threshold(x) < 5.0
    with pytest.raises(ValueError, match='rule'):
        denoise(x, rule='bayes')
    with pytest.raises(ValueError, match='wavelet'):
        denoise(x, wavelet='sym99')


@pytest.mark.slow
def test_sym8_12_levels_drop_white_noise_tenfold_keep_long_tau():
    """
    Thesis settings on simulated 3DM-GX3-25 data: white-noise ADEV down >= 10x, long tau kept.

    White-noise level = ADEV at tau = 1 s (where the thesis model is 98 % white noise, the
    IEEE read-off point of N).  Long tau = 160-520 s (> 4 x 2^12 samples, below T/10): the
    denoised ADEV must lie inside the original's 68.3 % intervals on every axis.
    """
    n = 2 ** 19  # 87 min at 100 Hz
    data = simulate(thesis_gx3_25_model(), n, RATE, seed=42)
    clean = denoise(data, RATE, wavelet='sym8', level=12)
    taus = np.array([1.0, 160.0, 250.0, 400.0, 520.0])
    before = allan_deviation(data, RATE, taus=taus)
    after = allan_deviation(clean, RATE, taus=taus)
    drop = before.adev[0] / after.adev[0]
    assert np.all(drop >= 10.0), drop
    long = slice(1, None)
    assert np.all(after.adev[long] >= before.ci_low[long])
    assert np.all(after.adev[long] <= before.ci_high[long])


def test_noise_from_allan_coeffs_equals_whole_record_batch(signal):
    """
    noise_source=allan: the stream equals the whole-record batch with sigma = N sqrt(fs).

    N comes from an imu/allan_coeffs payload; the threshold's n is the block length.
    """
    from imu_allan.nodes.denoise import white_noise_from_coeffs
    DIMS = [('axis', 6), ('term', 5), ('stat', 3)]  # noqa: N806
    table = np.full((6, 5, 3), np.nan)
    table[:, 1] = (0.1, 0.09, 0.11)  # white_noise row of every axis
    n = white_noise_from_coeffs(table.ravel().tolist(), DIMS)
    np.testing.assert_array_equal(n, np.full(6, 0.1))
    assert white_noise_from_coeffs([0.0] * 10, [('axis', 2), ('term', 5)]) is None
    table[2, 1, 0] = np.nan
    assert white_noise_from_coeffs(table.ravel(), DIMS) is None  # not detected everywhere
    bd = BlockDenoiser(RATE, 3, wavelet='sym8', level=4)
    bd.set_noise(noise_density=n[:3])
    out = _stream(bd, signal, seed=6)
    full = denoise(signal, RATE, wavelet='sym8', level=4, sigma=0.1 * np.sqrt(RATE),
                   n_ref=bd.block_len)
    np.testing.assert_allclose(out, full[:out.shape[0]], rtol=0, atol=1e-12)
