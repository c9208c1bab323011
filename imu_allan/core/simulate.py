"""
Time-series simulation of a :class:`~imu_allan.core.model.NoiseModel`.

Every term is generated with the statistics its analytic Allan variance assumes
(:mod:`imu_allan.core.terms`), so simulated curves and analytic curves can be compared:

* quantization Q: white phase noise of std Q, differenced (AVAR = 3 Q^2 / tau^2);
* white noise N: white rate noise of per-sample std N * sqrt(fs) (AVAR = N^2 / tau);
* bias instability B: true 1/f ("flicker") noise with two-sided PSD B^2 / (2 pi f) from far
  below 1/T up to the Nyquist frequency, made by shaping the spectrum of white noise (no
  Gauss-Markov approximation), so AVAR -> (2 ln 2 / pi) B^2 at long averaging times;
* rate random walk K: cumulative sum of steps of std K * sqrt(dt) (AVAR = K^2 tau / 3);
* rate ramp R: the deterministic line R * t (AVAR = R^2 tau^2 / 2);
* first-order Gauss-Markov (sigma, tau_c): stationary AR(1) with phi = exp(-dt / tau_c);
* sinusoid (amplitude, frequency_hz): a sine with a random phase.

All arrays are float64 with shape ``(n_samples, n_axes)``; units SI (rad/s, m/s^2).
"""

import math

import numpy as np

from .model import NoiseModel

#: The flicker series is generated this many times longer than asked for and cut, so that
#: frequencies down to 1/(FLICKER_SPAN T) are present: a real 1/f process has power below 1/T
#: that shows at averaging times near T/10 (without it their AVAR comes out ~10 % low).
FLICKER_SPAN = 8


def flicker_noise(rng, n, rate_hz, b):
    """
    1/f noise with two-sided PSD ``b^2 / (2 pi f)`` between 1/(FLICKER_SPAN T) and fs/2.

    Shaped white noise in the frequency domain: E|Z_k|^2 = S(f_k) * m * fs gives the discrete
    series the two-sided PSD S (periodogram convention |Y_k|^2 / (m fs)).
    """
    import scipy.fft
    if b == 0 or n == 0:
        return np.zeros(n)
    m = scipy.fft.next_fast_len(FLICKER_SPAN * n, real=True)
    freqs = np.fft.rfftfreq(m, d=1.0 / rate_hz)
    psd = np.zeros_like(freqs)
    psd[1:] = b * b / (2.0 * math.pi * freqs[1:])
    scale = np.sqrt(psd * m * rate_hz / 2.0)
    spectrum = scale * (rng.standard_normal(freqs.size) + 1j * rng.standard_normal(freqs.size))
    if m % 2 == 0:  # the Nyquist bin of a real series is real
        spectrum[-1] = math.sqrt(psd[-1] * m * rate_hz) * rng.standard_normal()
    spectrum[0] = 0.0
    return scipy.fft.irfft(spectrum, m)[:n]


def simulate_axis(terms, n_samples, rate_hz, rng):
    """Simulate one axis: ``terms`` maps term name -> parameter dict (SI)."""
    dt = 1.0 / rate_hz
    out = np.zeros(n_samples)
    if n_samples == 0:
        return out
    # Fixed draw order (not dict order) so a seed gives the same series for the same model.
    if 'white_noise' in terms:
        out += terms['white_noise']['value'] * math.sqrt(rate_hz) * rng.standard_normal(n_samples)
    if 'quantization' in terms:
        phase = terms['quantization']['value'] * rng.standard_normal(n_samples + 1)
        out += np.diff(phase) / dt
    if 'bias_instability' in terms:
        out += flicker_noise(rng, n_samples, rate_hz, terms['bias_instability']['value'])
    if 'rate_random_walk' in terms:
        steps = terms['rate_random_walk']['value'] * math.sqrt(dt) * rng.standard_normal(n_samples)
        out += np.cumsum(steps)
    if 'rate_ramp' in terms:
        out += terms['rate_ramp']['value'] * dt * np.arange(n_samples)
    if 'gauss_markov' in terms:
        import scipy.signal
        sigma, tau_c = terms['gauss_markov']['sigma'], terms['gauss_markov']['tau_c']
        phi = math.exp(-dt / tau_c)
        drive = sigma * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n_samples)
        drive[0] = sigma * rng.standard_normal()  # start in the stationary distribution
        out += scipy.signal.lfilter([1.0], [1.0, -phi], drive)
    if 'sinusoid' in terms:
        amp, f0 = terms['sinusoid']['amplitude'], terms['sinusoid']['frequency_hz']
        phase0 = rng.uniform(0.0, 2.0 * math.pi)
        out += amp * np.sin(2.0 * math.pi * f0 * dt * np.arange(n_samples) + phase0)
    return out


def simulate(model, n_samples, rate_hz, seed=None, axes=None):
    """
    Simulate ``n_samples`` at ``rate_hz`` from a noise model.

    Parameters
    ----------
    model : NoiseModel or dict
        The noise model (a dict is read as a model file's content).
    n_samples : int
        Number of samples per axis.
    rate_hz : float
        Sample rate, Hz.
    seed : int or numpy.random.Generator, optional
        Seed for reproducible output.
    axes : sequence of str, optional
        Axes to simulate (default: the model's axes, in the package's axis order).

    Returns
    -------
    numpy.ndarray
        Shape ``(n_samples, n_axes)``, SI units, zero mean apart from the noise itself.

    """
    if isinstance(model, dict):
        model = NoiseModel.from_dict(model)
    n_samples = int(n_samples)
    if n_samples < 0:
        raise ValueError('n_samples must be >= 0')
    if not rate_hz or rate_hz <= 0 or not math.isfinite(rate_hz):
        raise ValueError('rate_hz must be a positive number')
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    axes = list(axes) if axes is not None else model.axes
    out = np.empty((n_samples, len(axes)))
    for j, axis in enumerate(axes):
        out[:, j] = simulate_axis(model.terms.get(axis, {}), n_samples, rate_hz, rng)
    return out
