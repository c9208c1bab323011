"""Analytic Allan variance of each noise term (IEEE Std 952 / 1293), continuous time, SI.

All functions take averaging times ``tau`` (s, array) and return AVAR in (unit)^2:

=================  =====================================================  ==================
term               AVAR(tau)                                              ADEV slope
=================  =====================================================  ==================
quantization Q     3 Q^2 / tau^2                                          -1
white_noise N      N^2 / tau                                              -1/2
bias_instability B (2 B^2/pi) [ln2 - sin^3x (sin x + 4x cos x)/(2x^2)     0 (-> 0.664 B)
                   + Ci(2x) - Ci(4x)], x = pi f0 tau (exact flicker with
                   1/f PSD up to f0; f0 = Nyquist for sampled data)
rate_random_walk K K^2 tau / 3 (+ K^2 dt^2 / (6 tau) for sampled data)       +1/2
rate_ramp R        R^2 tau^2 / 2                                          +1
gauss_markov       2 s^2 Tc/tau [1 - Tc/(2 tau)(3 - 4e^(-tau/Tc)          +1/2 then -1/2
 (sigma s, tau_c)   + e^(-2 tau/Tc))] (stationary std s)
sinusoid (A, f0)   A^2 [sin^2(pi f0 tau) / (pi f0 tau)]^2                 bump at 0.371/f0
=================  =====================================================  ==================
"""

import math

import numpy as np
from scipy.special import sici

#: sqrt(2 ln 2 / pi): flat ADEV level of bias instability per unit B (not 0.644, not 0.798).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def flicker_shape(tau, f0):
    """AVAR of bias instability per unit B^2 with the 1/f PSD cut off at ``f0`` (Hz)."""
    x = math.pi * f0 * np.asarray(tau, dtype=float)
    ci2 = sici(2.0 * x)[1]
    ci4 = sici(4.0 * x)[1]
    s, c = np.sin(x), np.cos(x)
    return (2.0 / math.pi) * (math.log(2.0) - s ** 3 * (s + 4.0 * x * c) / (2.0 * x * x)
                              + ci2 - ci4)


def gauss_markov_shape(tau, tau_c):
    """AVAR of a first-order Gauss-Markov process per unit stationary variance sigma^2."""
    u = np.asarray(tau, dtype=float) / tau_c
    small = u < 1e-2
    with np.errstate(over='ignore', divide='ignore', invalid='ignore'):
        bracket = 1.0 - (-4.0 * np.expm1(-u) + np.expm1(-2.0 * u)) / (2.0 * u)
    # series of the bracket for u -> 0, where the closed form cancels catastrophically
    bracket = np.where(small, u * u / 3.0 - u ** 3 / 4.0 + 7.0 * u ** 4 / 120.0, bracket)
    return 2.0 * tau_c / np.asarray(tau, dtype=float) * bracket


def sinusoid_shape(tau, frequency_hz):
    """AVAR of a sinusoid per unit amplitude^2."""
    x = math.pi * frequency_hz * np.asarray(tau, dtype=float)
    return (np.sin(x) ** 2 / x) ** 2


def linear_shape(term, tau, rate_hz):
    """AVAR per unit squared coefficient for the five IEEE terms (linear in the square)."""
    tau = np.asarray(tau, dtype=float)
    if term == 'quantization':
        return 3.0 / tau ** 2
    if term == 'white_noise':
        return 1.0 / tau
    if term == 'bias_instability':
        return flicker_shape(tau, rate_hz / 2.0)
    if term == 'rate_random_walk':
        # tau/3 plus the exact correction for a sampled random walk, (2m^2 + 1) dt / (6m)
        return tau / 3.0 + 1.0 / (6.0 * rate_hz ** 2 * tau)
    if term == 'rate_ramp':
        return tau * tau / 2.0
    raise ValueError(f'{term} is not a single-coefficient term')


def term_avar(term, params, tau, rate_hz):
    """Analytic AVAR of one term with parameters ``params`` (dict, SI) at ``tau`` (s)."""
    if term == 'gauss_markov':
        return params['sigma'] ** 2 * gauss_markov_shape(tau, params['tau_c'])
    if term == 'sinusoid':
        return params['amplitude'] ** 2 * sinusoid_shape(tau, params['frequency_hz'])
    return params['value'] ** 2 * linear_shape(term, tau, rate_hz)


def model_avar(axis_terms, tau, rate_hz):
    """Sum of the analytic AVAR of every term of one axis (``{term: params}``)."""
    total = np.zeros(np.shape(tau))
    for term, params in axis_terms.items():
        total = total + term_avar(term, params, tau, rate_hz)
    return total
