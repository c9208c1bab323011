"""
One first-order Gauss-Markov bias in place of the bias terms a simulator cannot represent.

Gazebo (gz-sensors ``GaussianNoiseModel::ApplyImpl``, src/GaussianNoiseModel.cc:128-140) and
the PX4 SITL ``gazebo_imu_plugin`` (PX4-SITL_gazebo-classic src/gazebo_imu_plugin.cpp:195-213)
give each axis ONE first-order Gauss-Markov bias, set by its *driving* density sigma_b
(rad/s^2/sqrt(Hz) or m/s^3/sqrt(Hz), continuous time) and correlation time tau_c (s)::

    b_k = exp(-dt / tau_c) b_(k-1) + w_k,   var(w_k) = -sigma_b^2 tau_c / 2 expm1(-2 dt / tau_c)

(Maybeck eq. 4-114), whose stationary standard deviation is sigma_b sqrt(tau_c / 2): the
``sigma`` of the package's ``gauss_markov`` term.  For tau_c >> dt the step variance is
sigma_b^2 dt, a rate random walk of strength K = sigma_b.

Everything a noise model holds besides white noise and quantization (bias instability, random
walk, ramp, Gauss-Markov, sinusoid) must therefore become one Gauss-Markov when written for
these simulators: :func:`best_gauss_markov` finds it.  SI units, ROS-free.
"""

from dataclasses import dataclass
import math

import numpy as np

from .. import terms as _terms

#: The terms that only a simulator's Gauss-Markov bias can stand in for.
BIAS_TERMS = ('bias_instability', 'rate_random_walk', 'rate_ramp', 'gauss_markov', 'sinusoid')
#: A rate random walk is written as a Gauss-Markov with tau_c this many times the longest
#: averaging time: its AVAR there is K^2 tau / 3 (1 - 3 tau / (4 tau_c)), within 1 %.
RANDOM_WALK_TAU_FACTOR = 100.0
#: Averaging times per decade where a fitted Gauss-Markov is compared with the terms it replaces.
_GRID_PER_DECADE = 12


def driving_density(sigma, tau_c):
    """Driving density sigma_b of a Gauss-Markov with stationary std ``sigma`` (s: tau_c)."""
    return sigma * math.sqrt(2.0 / tau_c)


def stationary_sigma(drive, tau_c):
    """Stationary std of a Gauss-Markov with driving density ``drive`` (s: tau_c)."""
    return drive * math.sqrt(tau_c / 2.0)


@dataclass
class GaussMarkovFit:
    """
    The one Gauss-Markov standing in for an axis's bias terms.

    ``sigma`` is the stationary std (rad/s or m/s^2), ``tau_c`` the correlation time (s),
    ``replaces`` the terms it stands for, ``exact`` whether it reproduces them exactly
    (a single Gauss-Markov) or to within ``rms_log_error`` (rms of ln ADEV over ``tau_range``;
    a rate random walk is within 1 %), and ``how`` says which in words.
    """

    sigma: float
    tau_c: float
    replaces: tuple
    exact: bool
    rms_log_error: float
    tau_range: tuple
    how: str

    @property
    def drive(self):
        """Driving density sigma_b (continuous time, per sqrt(s))."""
        return driving_density(self.sigma, self.tau_c)


def best_gauss_markov(axis_terms, tau_range, rate_hz):
    """
    One Gauss-Markov matching the bias terms of one axis over ``tau_range`` (s, (lo, hi)).

    A single ``gauss_markov`` term is returned as it is; a lone rate random walk K becomes
    sigma_b = K with tau_c = :data:`RANDOM_WALK_TAU_FACTOR` x hi; anything else (bias
    instability, several terms, a ramp, a sinusoid) is fitted: the total Allan deviation with
    the Gauss-Markov (white noise and quantization kept) against the model's own, least squares
    in ln ADEV on a log grid over ``tau_range``, with tau_c between lo / 10 and 100 hi.
    Returns None when the axis has no bias term.
    """
    from scipy.optimize import least_squares

    present = tuple(t for t in BIAS_TERMS if t in axis_terms)
    if not present:
        return None
    lo, hi = float(tau_range[0]), float(tau_range[1])
    if present == ('gauss_markov',):
        p = axis_terms['gauss_markov']
        return GaussMarkovFit(p['sigma'], p['tau_c'], present, True, 0.0, (lo, hi),
                              'the Gauss-Markov itself')
    if present == ('rate_random_walk',):
        tau_c = RANDOM_WALK_TAU_FACTOR * hi
        sigma = stationary_sigma(axis_terms['rate_random_walk']['value'], tau_c)
        return GaussMarkovFit(sigma, tau_c, present, False, 0.0, (lo, hi),
                              f'a random walk: sigma_b = K with tau_c = '
                              f'{RANDOM_WALK_TAU_FACTOR:g} x {hi:.3g} s (within 1 % up to '
                              f'{hi:.3g} s)')
    tau = np.geomspace(lo, hi, max(8, int(_GRID_PER_DECADE * math.log10(hi / lo)) + 1))
    kept = {t: p for t, p in axis_terms.items() if t not in BIAS_TERMS}
    base = _terms.model_avar(kept, tau, rate_hz)
    target = _terms.model_avar(axis_terms, tau, rate_hz)
    excess = np.maximum(target - base, 1e-300)
    ln_target = np.log(target)
    bounds = ([math.log(lo / 10.0), -np.inf], [math.log(100.0 * hi), np.inf])

    # weights 1/sqrt(tau): the spread of a measured ln ADEV grows as sqrt(tau / T), so this is
    # the mismatch the Allan deviation of one record would see
    weight = np.sqrt(lo / tau)

    def residual(x):
        gm = math.exp(2.0 * x[1]) * _terms.gauss_markov_shape(tau, math.exp(x[0]))
        return 0.5 * (np.log(base + gm) - ln_target) * weight

    best = None
    for tau_c0 in np.geomspace(lo, hi, 7):
        shape = _terms.gauss_markov_shape(tau, tau_c0)
        sigma0 = math.sqrt(float(np.max(excess / shape)))
        x0 = [math.log(tau_c0), math.log(sigma0)]
        sol = least_squares(residual, x0, bounds=bounds, x_scale=1.0)
        if best is None or sol.cost < best.cost:
            best = sol
    tau_c, sigma = math.exp(best.x[0]), math.exp(best.x[1])
    rms = float(np.sqrt(np.mean((residual(best.x) / weight) ** 2)))
    return GaussMarkovFit(sigma, tau_c, present, False, rms, (lo, hi),
                          f'the Gauss-Markov closest to {" + ".join(present)} over '
                          f'{lo:.3g}-{hi:.3g} s (rms ln ADEV error {rms:.3f})')
