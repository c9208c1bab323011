"""Analytic Allan variance of each noise term (IEEE Std 952 / 1293), continuous time, SI.

All functions take averaging times ``tau`` (s, array) and return AVAR in (unit)^2:

=================  =====================================================  ==================
term               AVAR(tau)                                              ADEV slope
=================  =====================================================  ==================
quantization Q     3 Q^2 / tau^2                                          -1
white_noise N      N^2 / tau                                              -1/2
bias_instability B (2 B^2/pi) [ln2 - sin^3x (sin x + 4x cos x)/(2x^2)     0 (-> 0.664 B)
                   + Ci(2x) - Ci(4x)], x = pi f0 tau (exact flicker with
                   1/f PSD up to f0); for data sampled at fs the exact
                   discrete form (f0 = fs/2) is used, see sampled_flicker_shape
rate_random_walk K K^2 tau / 3 (+ K^2 dt^2 / (6 tau) for sampled data)       +1/2
rate_ramp R        R^2 tau^2 / 2                                          +1
gauss_markov       2 s^2 Tc/tau [1 - Tc/(2 tau)(3 - 4e^(-tau/Tc)          +1/2 then -1/2
 (sigma s, tau_c)   + e^(-2 tau/Tc))] (stationary std s)
sinusoid (A, f0)   A^2 [sin^2(pi f0 tau) / (pi f0 tau)]^2                 bump at 0.371/f0
=================  =====================================================  ==================
"""

import functools
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


#: Above this averaging factor the sampled and the continuous flicker curves agree to 1e-4.
_DISCRETE_FLICKER_MAX_M = 1000


@functools.lru_cache(maxsize=4096)
def _sampled_flicker(m):
    """AVAR per B^2 of a *sampled* 1/f series (PSD B^2/(2 pi f) up to Nyquist) at factor m.

    With the discrete transfer function of the difference of adjacent m-sample means,
    AVAR = 4 int_0^{fs/2} S(f) sin^4(pi f m dt) / (m^2 sin^2(pi f dt)) df; with u = pi f dt
    that is (2/pi) int_0^{pi/2} sin^4(m u) / (m^2 u sin^2 u) du, a function of m alone.  At
    m = 1, 2, 3 it is 40, 11 and 6 % above the continuous formula, which would bias a fit.
    """
    u = np.linspace(0.0, math.pi / 2.0, 128 * m + 1025)[1:]
    f = np.sin(m * u) ** 4 / (m * m * u * np.sin(u) ** 2)
    integral = np.sum((f[1:] + f[:-1]) * 0.5 * np.diff(u)) + 0.5 * f[0] * u[0]
    return 2.0 / math.pi * integral


def sampled_flicker_shape(tau, rate_hz):
    """AVAR per unit B^2 of bias instability for data sampled at ``rate_hz`` (exact)."""
    tau = np.asarray(tau, dtype=float)
    m = np.rint(tau * rate_hz).astype(np.int64)
    out = flicker_shape(tau, rate_hz / 2.0)
    small = (m >= 1) & (m <= _DISCRETE_FLICKER_MAX_M)
    out = np.array(out, dtype=float, copy=True, ndmin=1)
    out[np.atleast_1d(small)] = [_sampled_flicker(int(k)) for k in np.atleast_1d(m)[
        np.atleast_1d(small)]]
    return out.reshape(tau.shape)


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
        return sampled_flicker_shape(tau, rate_hz)
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
