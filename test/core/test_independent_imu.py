"""
The independent generator (independent_imu.py) against the closed-form Allan variances.

The calibration tables (live_calibration.py, startup_cases.py) are only as good as the truth
the generator is said to carry, so each noise it makes is checked here with a plain overlapping
Allan variance written in this file (no package code): white N^2 / tau, flicker
(2 ln 2 / pi) B^2, random walk K^2 tau / 3, quantization 3 Q^2 / tau^2 (IEEE Std 952 annex C),
and through the device's window and decimation the white density the output carries
(:meth:`IndependentAxis.white_truth`).  Mean of 12 records of 50 000 samples at 100 Hz
(fixed seeds); at the longest tau checked (m = 1000, 50 clusters over 12 records) the mean's
relative scatter is about 6 %, so a tolerance of 12 % is two standard errors at worst and far
below the errors that matter (a factor sqrt(2) in a density is 100 % in AVAR).
"""

import math

from core.independent_imu import Device, IndependentAxis
import numpy as np
import pytest

RATE = 100.0
N_SAMPLES = 50_000
MS = np.array([1, 10, 100, 1000])
REPS = 12


def _oavar(y, ms):
    """Overlapping AVAR of rate samples ``y`` at factors ``ms`` (phase differences)."""
    x = np.concatenate([[0.0], np.cumsum(y)]) / RATE
    out = []
    for m in ms:
        d = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
        out.append(np.mean(d * d) / (2.0 * (m / RATE) ** 2))
    return np.array(out)


def _mean_avar(truth, device=None):
    acc = np.zeros(MS.size)
    for seed in range(REPS):
        axis = IndependentAxis(truth, RATE, N_SAMPLES / RATE, np.random.default_rng(seed),
                               device)
        # in blocks, as the harnesses stream it: the blocks must join seamlessly
        y = np.concatenate([axis.take(N_SAMPLES // 4) for _ in range(4)])
        acc += _oavar(y, MS)
    return acc / REPS, axis


CASES = {
    'white': ({'white_noise': 1e-3}, lambda tau: 1e-6 / tau),
    # sampled flicker keeps its plateau from m = 10 (at m = 1 the bank's content near Nyquist
    # adds about half: checked from m = 10 only, as the fit's sampled shape accounts for it)
    'flicker': ({'bias_instability': 1e-3},
                lambda tau: 2.0 * math.log(2.0) / math.pi * 1e-6 * np.ones_like(tau)),
    # a sampled random walk: K^2 tau / 3 (1 + 1 / (2 m^2)), exact for a discrete walk
    'random walk': ({'rate_random_walk': 1e-4},
                    lambda tau: 1e-8 * tau / 3.0 * (1.0 + 0.5 / (tau * RATE) ** 2)),
}


@pytest.mark.parametrize('name', list(CASES))
def test_each_noise_has_its_closed_form_allan_variance(name):
    truth, closed = CASES[name]
    avar, _ = _mean_avar(truth)
    ratio = avar / closed(MS / RATE)
    if name == 'flicker':
        ratio = ratio[1:]
    assert np.all(np.abs(ratio - 1.0) < 0.12), (name, ratio)


def test_quantization_has_its_closed_form_where_it_dominates():
    """3 Q^2 / tau^2 at tau0 and 10 tau0 (beyond, the rounding's white part takes over)."""
    avar, _ = _mean_avar({'quantization': 1e-4})
    ratio = avar[:2] / (3.0 * 1e-8 / (MS[:2] / RATE) ** 2)
    assert np.all(np.abs(ratio - 1.0) < 0.12), ratio


@pytest.mark.parametrize('device', [Device(10, 15), Device(10, 7, 1.0)],
                         ids=['window 15 taps', 'window 7 taps, 1-sigma LSB'])
def test_device_output_carries_the_white_density_it_states(device):
    """Beyond the window (m >= 10), the output's AVAR is white_truth()^2 / tau."""
    avar, axis = _mean_avar({'white_noise': 1e-3}, device)
    ratio = avar[1:] / (axis.white_truth() ** 2 / (MS[1:] / RATE))
    assert np.all(np.abs(ratio - 1.0) < 0.12), ratio
    if device.taps > device.decimation:  # a window longer than the decimation shapes m = 1
        assert avar[0] < 0.8 * axis.white_truth() ** 2 / (MS[0] / RATE)
