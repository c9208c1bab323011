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

With ``processing`` (:class:`~imu_allan.core.simulation.device_processing.DeviceProcessing`) the
record is what such a device sends: the terms are generated at its internal rate, windowed,
decimated and rounded (float32), with the white noise scaled so that the output's low-frequency
density is the model's N; bias instability is generated at the output rate with the spectrum the
window and decimation give it.  A stream that goes on over many calls (the simulated 3DM-GX3-25) is
:class:`~imu_allan.core.simulation.noise_stream.NoiseStream`: :func:`simulate_axis` with a
``state``, every term at the internal rate.
"""

import functools
import math

import numpy as np

from ..model import NoiseModel
from ..units import discrete_random_walk_step, discrete_white_std

#: The flicker series is generated this many times longer than asked for and cut, so that
#: frequencies down to 1/(FLICKER_SPAN T) are present: a real 1/f process has power below 1/T
#: that shows at averaging times near T/10 (without it their AVAR comes out ~10 % low).
FLICKER_SPAN = 8


def flicker_noise(rng, n, rate_hz, b, processing=None):
    """
    1/f noise with two-sided PSD ``b^2 / (2 pi f)`` between 1/(FLICKER_SPAN T) and fs/2.

    Shaped white noise in the frequency domain: E|Z_k|^2 = S(f_k) * m * fs gives the discrete
    series the two-sided PSD S (periodogram convention |Y_k|^2 / (m fs)).  With
    ``processing`` (``rate_hz`` its output rate) S is the PSD that 1/f noise at the internal
    rate has after the window and decimation (``DeviceProcessing.output_psd``): the same
    second-order statistics as generating it at the internal rate, at a tenth of the cost.
    """
    import scipy.fft
    if b == 0 or n == 0:
        return np.zeros(n)
    m = scipy.fft.next_fast_len(FLICKER_SPAN * n, real=True)
    freqs = np.fft.rfftfreq(m, d=1.0 / rate_hz)
    psd = np.zeros_like(freqs)
    if processing is None:
        psd[1:] = b * b / (2.0 * math.pi * freqs[1:])
    else:
        psd[1:] = b * b * _processed_flicker_psd(m, rate_hz, processing)
    scale = np.sqrt(psd * m * rate_hz / 2.0)
    spectrum = scale * (rng.standard_normal(freqs.size) + 1j * rng.standard_normal(freqs.size))
    if m % 2 == 0:  # the Nyquist bin of a real series is real
        spectrum[-1] = math.sqrt(psd[-1] * m * rate_hz) * rng.standard_normal()
    spectrum[0] = 0.0
    return scipy.fft.irfft(spectrum, m)[:n]


@functools.lru_cache(maxsize=1)
def _processed_flicker_psd(m, rate_hz, processing):
    """
    PSD of processed 1/f noise of unit level at the positive frequencies of an m-point FFT.

    Kept for the next call: the axes of one record share it (a second each at 2 h, 100 Hz).
    """
    freqs = np.fft.rfftfreq(m, d=1.0 / rate_hz)[1:]
    psd = processing.output_psd(freqs, lambda f: 1.0 / (2.0 * math.pi * f))
    psd.flags.writeable = False
    return psd


#: Flicker of a stream: a bank of first-order (AR(1)) sections, two per decade, with corners
#: (as fractions of the sample rate) from the Nyquist frequency down ten decades.  Lorentzians
#: evenly spaced in log frequency with equal variances B^2 ln(10) / (2 pi) add up to the
#: two-sided PSD B^2 / (2 pi f) between the corners; the top three weights were fitted (NNLS)
#: to the exact Allan variance of sampled 1/f noise (terms.sampled_flicker_shape), which the
#: bank's exact Allan variance then matches within 1.6 % at m = 2 and 0.8 % at every m from 3
#: to 1e8 samples (test_simulate.py).  Each section carries its value from call to call.
FLICKER_BANK_CORNERS = 0.5 * 10.0 ** (-np.arange(21) / 2.0)
FLICKER_BANK_WEIGHTS = np.concatenate([[0.2094, 1.3384, 0.9481], np.ones(18)])


def flicker_bank(rng, n, b, state):
    """
    ``n`` samples of 1/f noise of level ``b`` that continue the bank's ``state`` (a dict).

    The sections' values at the last sample are kept in ``state['flicker']``; the first call
    draws them from the stationary distribution.
    """
    phi = np.exp(-2.0 * math.pi * FLICKER_BANK_CORNERS)
    sigma = b * np.sqrt(FLICKER_BANK_WEIGHTS * math.log(10.0) / (2.0 * math.pi))
    last = state.get('flicker')
    if last is None:
        last = sigma * rng.standard_normal(phi.size)
    # one row of draws per sample: the stream does not depend on how it is cut into calls
    drive = rng.standard_normal((n, phi.size)) * (sigma * np.sqrt(1.0 - phi * phi))
    out = np.empty(n)
    for start in range(0, n, _SCAN_ROWS):
        sections = ar1_scan(drive[start:start + _SCAN_ROWS], phi, last)
        last = sections[-1]
        out[start:start + len(sections)] = sections.sum(axis=1)
    state['flicker'] = last
    return out


#: Rows per :func:`ar1_scan` call: its cost grows as n log n.
_SCAN_ROWS = 1024


def ar1_scan(drive, phi, last):
    """
    x_i = phi x_(i-1) + drive_i down each column (its own phi), from x_(-1) = ``last``.

    A doubling scan: after the step of shift s every x_i holds the drives of its last 2s
    samples, so log2(n) vectorized steps replace a loop over the samples.  Numpy alone:
    scipy.signal's lfilter would cost 1-2 s of import in every simulator start.
    """
    x = np.array(drive, dtype=float)
    n = len(x)
    shifted = np.empty_like(x)
    shift = 1
    while shift < n:
        np.multiply(x[:n - shift], phi ** shift, out=shifted[:n - shift])
        x[shift:] += shifted[:n - shift]
        shift *= 2
    return x + np.power.outer(phi, np.arange(1, n + 1)).T * last


def simulate_axis(terms, n_samples, rate_hz, rng, state=None):
    """
    Simulate one axis: ``terms`` maps term name -> parameter dict (SI).

    ``state`` is None for a record on its own.  A dict (empty at first) makes the axis a stream
    that continues over calls: each term goes on from where the last call ended (quantization
    phase, random-walk level, Gauss-Markov value, ramp and sinusoid time, all kept in the
    dict), and bias instability comes from :func:`flicker_bank` instead of the FFT.
    """
    dt = 1.0 / rate_hz
    out = np.zeros(n_samples)
    if n_samples == 0:
        return out
    stream = state is not None
    # sample numbers since the stream began (the ramp's and the sinusoid's time)
    index = np.arange(n_samples) + (state.get('n', 0) if stream else 0)
    # Fixed draw order (not dict order) so a seed gives the same series for the same model.
    if 'white_noise' in terms:
        out += (discrete_white_std(terms['white_noise']['value'], rate_hz)
                * rng.standard_normal(n_samples))
    if 'quantization' in terms:
        q = terms['quantization']['value']
        if stream and 'phase' in state:
            phase = np.concatenate([[state['phase']], q * rng.standard_normal(n_samples)])
        else:
            phase = q * rng.standard_normal(n_samples + 1)
        out += np.diff(phase) / dt
        if stream:
            state['phase'] = phase[-1]
    if 'bias_instability' in terms:
        b = terms['bias_instability']['value']
        out += flicker_bank(rng, n_samples, b, state) if stream \
            else flicker_noise(rng, n_samples, rate_hz, b)
    if 'rate_random_walk' in terms:
        steps = (discrete_random_walk_step(terms['rate_random_walk']['value'], rate_hz)
                 * rng.standard_normal(n_samples))
        walk = np.cumsum(steps)
        if stream:
            walk += state.get('walk', 0.0)
            state['walk'] = walk[-1]
        out += walk
    if 'rate_ramp' in terms:
        out += terms['rate_ramp']['value'] * dt * index
    if 'gauss_markov' in terms:
        import scipy.signal
        sigma, tau_c = terms['gauss_markov']['sigma'], terms['gauss_markov']['tau_c']
        phi = math.exp(-dt / tau_c)
        if stream and 'gauss_markov' not in state:  # the value before the first sample
            state['gauss_markov'] = sigma * rng.standard_normal()
        drive = sigma * math.sqrt(1.0 - phi * phi) * rng.standard_normal(n_samples)
        if stream:
            values, _ = scipy.signal.lfilter([1.0], [1.0, -phi], drive,
                                             zi=[phi * state['gauss_markov']])
            state['gauss_markov'] = values[-1]
        else:
            drive[0] = sigma * rng.standard_normal()  # start in the stationary distribution
            values = scipy.signal.lfilter([1.0], [1.0, -phi], drive)
        out += values
    if 'sinusoid' in terms:
        amp, f0 = terms['sinusoid']['amplitude'], terms['sinusoid']['frequency_hz']
        phase0 = state.get('sinusoid_phase') if stream else None
        if phase0 is None:
            phase0 = rng.uniform(0.0, 2.0 * math.pi)
        if stream:
            state['sinusoid_phase'] = phase0
        out += amp * np.sin(2.0 * math.pi * f0 * dt * index + phase0)
    if stream:
        state['n'] = index[-1] + 1
    return out


def scaled_white(terms, processing):
    """
    One axis's terms with the white noise at the internal density N / sqrt(alias gain).

    So that the output's low-frequency density is the model's N
    (:mod:`imu_allan.core.simulation.device_processing`); the other terms are unchanged.
    """
    if 'white_noise' not in terms:
        return terms
    white = dict(terms['white_noise'])
    white['value'] = white['value'] / math.sqrt(processing.alias_gain)
    return {**terms, 'white_noise': white}


def simulate(model, n_samples, rate_hz, seed=None, axes=None, processing=None):
    """
    Simulate ``n_samples`` per axis at ``rate_hz`` (Hz) from a noise model; ``(n, A)``, SI.

    ``model`` is a NoiseModel or a model file's content (dict); ``seed`` an int or a numpy
    Generator; ``axes`` the axes to simulate (default: the model's, in the package's order).
    ``processing`` (a :class:`.device_processing.DeviceProcessing`) is the device's window,
    decimation and rounding, ``rate_hz`` its output rate (ValueError otherwise); None gives
    unrounded samples at ``rate_hz``.  Zero mean apart from the noise itself.
    """
    if isinstance(model, dict):
        model = NoiseModel.from_dict(model)
    n_samples = int(n_samples)
    if n_samples < 0:
        raise ValueError('n_samples must be >= 0')
    if not rate_hz or rate_hz <= 0 or not math.isfinite(rate_hz):
        raise ValueError('rate_hz must be a positive number')
    if processing is not None:
        processing.check_rate(rate_hz)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    axes = list(axes) if axes is not None else model.axes
    out = np.empty((n_samples, len(axes)))
    for j, axis in enumerate(axes):
        terms = model.terms.get(axis, {})
        if processing is None:
            out[:, j] = simulate_axis(terms, n_samples, rate_hz, rng)
            continue
        # Every term at the internal rate through the window, but bias instability: its FFT
        # would cost ten times the samples, and its shaped spectrum is exact at the output rate.
        inner = dict(scaled_white(terms, processing))
        flicker = inner.pop('bias_instability', None)
        # the window - 1 samples before the first output, then decimation per output
        n_inner = processing.window - 1 + n_samples * processing.decimation
        internal = simulate_axis(inner, n_inner, processing.internal_rate_hz, rng)
        out[:, j] = processing.filter_decimate(internal)
        if flicker is not None:
            out[:, j] += flicker_noise(rng, n_samples, rate_hz, flicker['value'], processing)
    return out if processing is None else processing.rounded(out)
