"""
The noise-term registry (:data:`TERMS`) and the analytic Allan variance of each term.

One :class:`TermSpec` per term holds its parameters and units, power-law exponent, Allan
shape, peak ratio and conventional units; the estimator, the fit, the discrepancy workflow,
the units and the reports read them from here (IEEE Std 952 / 1293; continuous time, SI).

The shape functions take averaging times ``tau`` (s, array) and return AVAR in (unit)^2:

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

from dataclasses import dataclass, field
import functools
import math
from typing import Callable, Optional

import numpy as np

#: sqrt(2 ln 2 / pi): flat ADEV level of bias instability per unit B (not 0.644, not 0.798).
FLICKER_FLOOR = math.sqrt(2.0 * math.log(2.0) / math.pi)


def flicker_shape(tau, f0):
    """AVAR of bias instability per unit B^2 with the 1/f PSD cut off at ``f0`` (Hz)."""
    x = math.pi * f0 * np.asarray(tau, dtype=float)
    s, c = np.sin(x), np.cos(x)
    return (2.0 / math.pi) * (math.log(2.0) - s ** 3 * (s + 4.0 * x * c) / (2.0 * x * x)
                              + cosine_integral(2.0 * x) - cosine_integral(4.0 * x))


#: From here on Ci(z) is summed from its asymptotic series (8 terms: error below 1e-19).
_CI_SERIES_MIN = 100.0
_CI_F = [(-1) ** k * math.factorial(2 * k) for k in range(8)]      # of f(z) z
_CI_G = [(-1) ** k * math.factorial(2 * k + 1) for k in range(8)]  # of g(z) z^2


def cosine_integral(z):
    """
    Ci(z) = -int_z^inf cos(t) / t dt for z > 0.

    For z >= 100 (the flicker curve's arguments at averaging factors above 1000, where
    :func:`sampled_flicker_shape` uses the continuous curve) from Ci = f sin z - g cos z with
    the auxiliary functions' asymptotic series (Abramowitz & Stegun 5.2.9, 5.2.34-35),
    truncated after 8 terms, the last of which is below 2e-19 there; this avoids importing
    scipy.special (0.3 s).  Smaller arguments use scipy's ``sici``.
    """
    z = np.asarray(z, dtype=float)
    if not np.all(z >= _CI_SERIES_MIN):
        from scipy.special import sici
        return sici(z)[1]
    w = 1.0 / (z * z)
    f = np.polynomial.polynomial.polyval(w, _CI_F) / z
    g = np.polynomial.polynomial.polyval(w, _CI_G) * w
    return f * np.sin(z) - g * np.cos(z)


#: Above this averaging factor the sampled and the continuous flicker curves agree to 1e-4.
_DISCRETE_FLICKER_MAX_M = 1000


@functools.lru_cache(maxsize=4096)
def _sampled_flicker(m, power=4):
    """
    AVAR per B^2 of a *sampled* 1/f series (PSD B^2/(2 pi f) up to Nyquist) at factor m.

    With the discrete transfer function of the difference of adjacent m-sample means,
    AVAR = 4 int_0^{fs/2} S(f) sin^4(pi f m dt) / (m^2 sin^2(pi f dt)) df; with u = pi f dt
    that is (2/pi) int_0^{pi/2} sin^4(m u) / (m^2 u sin^2 u) du, a function of m alone.  At
    m = 1, 2, 3 it is 40, 11 and 6 % above the continuous formula, which would bias a fit.
    ``power=6`` gives the Hadamard variance, (2/pi) int (4/3) sin^6(m u) / (m^2 u sin^2 u) du,
    which tends to :data:`HADAMARD_FLICKER_FLOOR`.

    Integrated by 16-point Gauss-Legendre between consecutive zeros of sin(m u) (the integrand
    is smooth there): converged to 1e-15 (48 points agree), where the trapezoid rule on 128
    points per period it replaced was 1.75e-5 low and twelve times slower.
    """
    edges = np.unique(np.minimum(np.arange(m // 2 + 2) * (math.pi / m), math.pi / 2.0))
    half = 0.5 * np.diff(edges)[:, None]
    u = half * _GL16[0] + (edges[:-1, None] + half)
    f = np.sin(m * u) ** power / (m * m * u * np.sin(u) ** 2)
    scale = 2.0 / math.pi if power == 4 else 8.0 / (3.0 * math.pi)
    return scale * float(np.sum(f * half * _GL16[1]))


_GL16 = np.polynomial.legendre.leggauss(16)  # nodes on [-1, 1] and weights


def sampled_flicker_shape(tau, rate_hz):
    """AVAR per unit B^2 of bias instability for data sampled at ``rate_hz`` (exact)."""
    tau = np.asarray(tau, dtype=float)
    flat = np.atleast_1d(tau)
    m = np.rint(flat * rate_hz).astype(np.int64)
    small = (m >= 1) & (m <= _DISCRETE_FLICKER_MAX_M)
    out = np.empty(flat.shape)
    out[small] = [_sampled_flicker(int(k)) for k in m[small]]
    if not small.all():
        out[~small] = flicker_shape(flat[~small], rate_hz / 2.0)
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


def band_shape(tau, f_lo, f_hi, points=64):
    """
    AVAR per unit variance of noise spread evenly over the band [f_lo, f_hi] Hz (a resonance).

    Each frequency f in it contributes as a sinusoid of that power does (amplitude^2 = 2 x
    power): 2 sin^4(pi f tau) / (pi f tau)^2, averaged over the band (``points`` midpoints).
    """
    f = f_lo + (np.arange(points) + 0.5) * ((f_hi - f_lo) / points)
    x = math.pi * np.asarray(tau, dtype=float)[..., None] * f
    return 2.0 * np.mean((np.sin(x) ** 2 / x) ** 2, axis=-1)


def quantization_shape(tau):
    """AVAR of quantization noise per unit Q^2: 3 / tau^2 (IEEE Std 952, Table C.1)."""
    return 3.0 / np.asarray(tau, dtype=float) ** 2


def white_shape(tau):
    """AVAR of white rate noise per unit N^2: 1 / tau."""
    return 1.0 / np.asarray(tau, dtype=float)


def random_walk_shape(tau, rate_hz=None):
    """
    AVAR of a rate random walk per unit K^2: tau / 3.

    With ``rate_hz`` the exact correction for a *sampled* random walk is added: the AVAR of
    a cumulative sum of white steps at factor m is K^2 dt (2 m^2 + 1) / (6 m), i.e.
    tau / 3 + dt^2 / (6 tau).
    """
    tau = np.asarray(tau, dtype=float)
    if rate_hz is None:
        return tau / 3.0
    return tau / 3.0 + 1.0 / (6.0 * rate_hz ** 2 * tau)


def ramp_shape(tau):
    """AVAR of a rate ramp per unit R^2: tau^2 / 2."""
    return np.asarray(tau, dtype=float) ** 2 / 2.0


def _flat(tau):
    return np.ones_like(np.asarray(tau, dtype=float))


DEG = math.pi / 180.0
HOUR = 3600.0
#: Standard gravity, m/s^2 per g (for conventional mg; re-exported by :mod:`.units`).
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class TermSpec:
    """Everything the package knows about one noise term, in one place."""

    #: key (``white_noise``) and IEEE symbol (``N``)
    name: str
    symbol: str
    #: parameter names: the first is the amplitude (AVAR is linear in its square), the second,
    #: for hump terms, the position (``tau_c`` in s or ``frequency_hz`` in Hz)
    params: tuple
    #: frequency-PSD power-law exponent of the estimate's noise (drives the EDF and the
    #: correlation between averaging times; Greenhall & Riley 2004 notation): +2 white PM, 0
    #: white FM, -1 flicker FM, -2 random-walk FM.  None for deterministic terms, whose estimate
    #: carries no randomness of its own; Gauss-Markov depends on tau (:meth:`alpha_at`)
    alpha: Optional[int]
    #: log-log slope of the Allan deviation (IEEE Std 952 Fig. C.1), for people
    adev_slope: str
    #: per sensor (``gyro``, ``accel``): the SI unit of the amplitude (continuous time) and
    #: ``(label, factor)`` with conventional = SI * factor
    si_units: dict
    conventional: dict
    #: hump terms: where the Allan deviation peaks, tau_peak / tau_c (Gauss-Markov) or
    #: tau_peak * f0 (sinusoid)
    peak_ratio: float = None
    #: continuous-time AVAR shape per unit squared amplitude that identifies the dominant noise
    #: at each averaging time (no sampling corrections)
    id_shape: Callable = None
    #: the exponent identification counts where the term dominates, if not ``alpha`` (the
    #: deterministic ramp: random-walk FM, the most conservative EDF there)
    id_alpha: int = None
    #: SI unit of each position parameter
    position_units: dict = field(default_factory=dict)

    @property
    def deterministic(self):
        """Return True for terms whose Allan variance estimate carries no randomness of its own."""
        return self.alpha is None and self.name != 'gauss_markov'

    @property
    def position(self):
        """Name of the position parameter of a hump term, else None."""
        return self.params[1] if len(self.params) > 1 else None

    def shape(self, tau, rate_hz, position=None):
        """AVAR per unit squared amplitude at ``tau`` (s) for data sampled at ``rate_hz``."""
        return _SHAPES[self.name](tau, rate_hz, position)

    def avar(self, params, tau, rate_hz):
        """Analytic AVAR of this term with ``params`` (dict, SI) at ``tau`` (s)."""
        amplitude, position = self.unpack(params)
        return amplitude ** 2 * self.shape(tau, rate_hz, position)

    def pack(self, amplitude, position=None):
        """Parameter dict from the amplitude (and the position of a hump term)."""
        if self.position is None:
            return {self.params[0]: amplitude}
        return {self.params[0]: amplitude, self.params[1]: position}

    def unpack(self, params):
        """``(amplitude, position or None)`` from a parameter dict."""
        return params[self.params[0]], (params[self.params[1]] if self.position else None)

    def alpha_at(self, tau, params=None):
        """
        Noise exponent per averaging time (array); 0 for deterministic terms.

        A Gauss-Markov process looks like a random walk (-2) below its correlation time and
        like white noise (0) above it.
        """
        tau = np.asarray(tau, dtype=float)
        if self.name == 'gauss_markov':
            return np.where(tau >= params['tau_c'], 0, -2)
        return np.full(tau.shape, 0 if self.alpha is None else self.alpha, dtype=int)

    def position_range(self, tau_lo, tau_hi):
        """Positions whose Allan-deviation peak lies inside ``[tau_lo, tau_hi]`` (s)."""
        return tuple(sorted((self.position_at_peak(tau_lo), self.position_at_peak(tau_hi))))

    def position_at_peak(self, tau_peak):
        """Return the position that puts the Allan-deviation peak at ``tau_peak`` (s)."""
        if self.name == 'gauss_markov':
            return tau_peak / self.peak_ratio
        return self.peak_ratio / tau_peak

    def param_unit(self, axis, param):
        """SI unit of one parameter for an axis (``tau_c`` s, ``frequency_hz`` Hz)."""
        if param in self.position_units:
            return self.position_units[param]
        return self.si_units['gyro' if axis.startswith('gyro') else 'accel']


def _conv(gyro, accel):
    return {'gyro': gyro, 'accel': accel}


_SHAPES = {
    'quantization': lambda tau, rate, _pos: quantization_shape(tau),
    'white_noise': lambda tau, rate, _pos: white_shape(tau),
    'bias_instability': lambda tau, rate, _pos: sampled_flicker_shape(tau, rate),
    'rate_random_walk': lambda tau, rate, _pos: random_walk_shape(tau, rate),
    'rate_ramp': lambda tau, rate, _pos: ramp_shape(tau),
    'gauss_markov': lambda tau, rate, pos: gauss_markov_shape(tau, pos),
    'sinusoid': lambda tau, rate, pos: sinusoid_shape(tau, pos),
}

#: The registry: one :class:`TermSpec` per term, in the package's term order.
TERMS = {spec.name: spec for spec in (
    TermSpec('quantization', 'Q', ('value',), 2, '-1',
             _conv('rad', 'm/s'), _conv(('deg', 1.0 / DEG), ('m/s', 1.0)),
             id_shape=quantization_shape),
    TermSpec('white_noise', 'N', ('value',), 0, '-1/2',
             _conv('rad/s/sqrt(Hz)', 'm/s^2/sqrt(Hz)'),
             _conv(('deg/sqrt(h)', math.sqrt(HOUR) / DEG), ('m/s/sqrt(h)', math.sqrt(HOUR))),
             id_shape=white_shape),
    TermSpec('bias_instability', 'B', ('value',), -1, '0',
             _conv('rad/s', 'm/s^2'), _conv(('deg/h', HOUR / DEG), ('m/s/h', HOUR)),
             id_shape=_flat),
    TermSpec('rate_random_walk', 'K', ('value',), -2, '+1/2',
             _conv('rad/s^2/sqrt(Hz)', 'm/s^3/sqrt(Hz)'),
             _conv(('deg/h/sqrt(h)', HOUR * math.sqrt(HOUR) / DEG),
                   ('m/s/h/sqrt(h)', HOUR * math.sqrt(HOUR))),
             id_shape=random_walk_shape),
    TermSpec('rate_ramp', 'R', ('value',), None, '+1',
             _conv('rad/s^2', 'm/s^3'), _conv(('deg/h^2', HOUR * HOUR / DEG),
                                              ('m/s/h^2', HOUR * HOUR)),
             id_shape=ramp_shape, id_alpha=-2),
    # peak ratios: maximum of gauss_markov_shape(tau, 1), and tan(x) = 2x for the sinusoid
    # (x = pi f0 tau); both computed to 1e-10 and rounded here.
    TermSpec('gauss_markov', 'GM', ('sigma', 'tau_c'), None, '+1/2 then -1/2',
             _conv('rad/s', 'm/s^2'), _conv(('deg/h', HOUR / DEG), ('m/s/h', HOUR)),
             peak_ratio=1.892618, position_units={'tau_c': 's'}),
    TermSpec('sinusoid', 'S', ('amplitude', 'frequency_hz'), None, 'bump',
             _conv('rad/s', 'm/s^2'), _conv(('deg/s', 1.0 / DEG), ('mg', 1e3 / STANDARD_GRAVITY)),
             peak_ratio=0.371010, position_units={'frequency_hz': 'Hz'}),
)}


@dataclass(frozen=True)
class RunTermSpec:
    """
    A run-to-run term: drawn once per run, constant within it, so no Allan variance of its own.

    ``params`` its parameter names, ``si_units`` / ``conventional`` as for :class:`TermSpec`.
    """

    name: str
    params: tuple
    si_units: dict
    conventional: dict


#: The turn-on bias of a model file: a constant bias per axis drawn at each start from a normal
#: distribution with ``mean`` and ``sigma`` (rad/s, m/s^2).  One run cannot show it; several
#: runs can (the discrepancy workflow's run_to_run evidence).
TURN_ON_BIAS = RunTermSpec('turn_on_bias', ('mean', 'sigma'), _conv('rad/s', 'm/s^2'),
                           _conv(('deg/h', HOUR / DEG), ('mg', 1e3 / STANDARD_GRAVITY)))

#: Exponent used for noise identification where a term dominates (the terms with an
#: ``id_shape``, in registry order; :attr:`TermSpec.id_alpha`).
ID_ALPHA = {name: spec.alpha if spec.id_alpha is None else spec.id_alpha
            for name, spec in TERMS.items() if spec.id_shape is not None}


def term_avar(term, params, tau, rate_hz):
    """Analytic AVAR of one term with parameters ``params`` (dict, SI) at ``tau`` (s)."""
    return TERMS[term].avar(params, tau, rate_hz)


def model_avar(axis_terms, tau, rate_hz):
    """Sum of the analytic AVAR of every term of one axis (``{term: params}``)."""
    total = np.zeros(np.shape(tau))
    for term, params in axis_terms.items():
        total = total + term_avar(term, params, tau, rate_hz)
    return total


# --- Hadamard variance of each IEEE term -------------------------------------------------
# The overlapping Hadamard variance (SP1065 eq 20) is (1/6) E[(ybar_2 - 2 ybar_1 + ybar_0)^2]
# of adjacent tau-averages.  Its transfer function is the Allan one times (4/3) sin^2(pi f tau),
# so a constant rate slope (the ramp R) cancels exactly, and the random walk and flicker weigh
# less.  Every shape is the exact one for sampled data, per unit squared amplitude.

#: HVAR / B^2 of flicker at long tau: (8 / 3 pi) int_0^inf sin^6 x / x^3 dx
#: = (4 ln 2 - 1.5 ln 3) / pi = 0.35800 (against 2 ln 2 / pi = 0.44127 for AVAR).
HADAMARD_FLICKER_FLOOR = (4.0 * math.log(2.0) - 1.5 * math.log(3.0)) / math.pi


def hadamard_shape(name, tau, rate_hz):
    """
    Overlapping Hadamard variance per unit squared amplitude of an IEEE term (exact, sampled).

    Q: 10 Q^2 / (3 tau^2) (third difference of white phase: 20 Q^2 / tau^2, over 6);
    N: N^2 / tau (as AVAR); B: :func:`_sampled_flicker` (``power=6``); K: K^2 (tau / 6 +
    dt^2 / (6 tau)) (the third difference of a sampled walk: sum of squared tail weights
    (m^2 + 1) / m, over 6; half the Allan tau / 3); R: 0 (a constant slope cancels).
    """
    tau = np.asarray(tau, dtype=float)
    if name == 'quantization':
        return 10.0 / (3.0 * tau ** 2)
    if name == 'white_noise':
        return 1.0 / tau
    if name == 'bias_instability':
        m = np.maximum(np.rint(np.atleast_1d(tau) * rate_hz).astype(np.int64), 1)
        return np.array([_sampled_flicker(int(k), 6) for k in m]).reshape(tau.shape)
    if name == 'rate_random_walk':
        return tau / 6.0 + 1.0 / (6.0 * rate_hz ** 2 * tau)
    if name == 'rate_ramp':
        return np.zeros_like(tau)
    raise ValueError(f'no Hadamard variance for the term {name!r}')
