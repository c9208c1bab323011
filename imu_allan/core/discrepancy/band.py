"""
Where the measured log-deviation of an axis should lie if a noise model were complete.

The :class:`Band` (analytic centre and spread of ln adev, from the model's terms and their
Greenhall EDF, pooled with simulations) and the :class:`Gap` between measured data and a band;
the method is described in :mod:`imu_allan.core.discrepancy` and ``docs/discrepancy.md``.
"""

from dataclasses import dataclass
import functools
import math

import numpy as np
from scipy.stats import chi2

from ..allan.edf import edf_oadev
from ..allan.log_chi2 import log_bias, log_sd
from ..fit import correlation_matrix, Problem
from ..terms import TERMS

#: Weight (pseudo-observations) of the analytic EDF spread when pooled with simulations.
PRIOR_WEIGHT = 16.0
#: Default significance level: for calling a model inconsistent and for adding an effect.
ALPHA = 0.01
Z95 = 1.959964


@functools.lru_cache(maxsize=4096)
def _edf(alpha, m, n_phase):
    return edf_oadev(alpha, int(m), int(n_phase))


def _term_edf(term, params, tau, ms, n_samples):
    """EDF of the AVAR estimate if ``term`` alone were present; inf for deterministic terms."""
    spec = TERMS[term]
    if spec.deterministic:
        return np.full(tau.shape, np.inf)
    alphas = spec.alpha_at(tau, params)
    return np.array([_edf(int(a), int(m), n_samples + 1) for a, m in zip(alphas, ms)])


@dataclass
class Band:
    """
    Expected measured log-deviation of one axis under a model (arrays over ``tau``, s).

    ``avar`` is the analytic model AVAR (unit^2), ``edf`` the model EDF of each estimate (the
    terms' EDFs mixed harmonically by AVAR share), ``alpha`` the exponent of the dominant
    random term (it sets the correlation between averaging times), ``center`` the expected
    ln(adev) 0.5 ln AVAR + 0.5 (psi(nu/2) - ln(nu/2)), ``sd`` its standard deviation (analytic
    0.5 sqrt(psi'(nu/2)), pooled with simulations), ``sims`` the (K, T) ln(adev) of the
    simulated runs or None.
    """

    tau: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    center: np.ndarray
    sd: np.ndarray
    sims: np.ndarray = None

    @property
    def corr(self):
        """Correlation of the estimates between averaging times."""
        return correlation_matrix(self.tau, self.alpha)

    def effective_count(self):
        """T_eff = T^2 / sum rho_ij^2: independent averaging times equivalent to the curve."""
        return effective_count(self.corr)

    def problem(self, y, rate_hz):
        """
        Return the fit :class:`~imu_allan.core.fit.Problem` of measured ln(adev) ``y`` here.

        Its ln AVAR level is 2 (y - the band's log bias) and its spread 2 sd (ln AVAR is twice
        ln adev), so its whitened residuals are the gap's z; ``rate_hz`` the sample rate (Hz).
        """
        bias = self.center - 0.5 * np.log(self.avar)
        return Problem.from_log_level(self.tau, 2.0 * (y - bias), 2.0 * self.sd, self.corr,
                                      self.alpha, rate_hz)

    def adev_band(self, z=Z95):
        """(low, centre, high) of the deviation at +-z spreads (unit of the samples)."""
        return (np.exp(self.center - z * self.sd), np.exp(self.center),
                np.exp(self.center + z * self.sd))


def effective_count(corr):
    """T^2 / sum rho_ij^2 of a correlation matrix: the independent points it is worth."""
    return corr.shape[0] ** 2 / float(np.sum(corr * corr))


def model_band(axis_terms, tau, ms, n_samples, rate_hz):
    """Analytic :class:`Band` of one axis (``axis_terms``: ``{term: params}``, SI)."""
    tau = np.asarray(tau, dtype=float)
    contrib = {t: np.maximum(TERMS[t].avar(p, tau, rate_hz), 0.0)
               for t, p in axis_terms.items()}
    total = np.maximum(sum(contrib.values(), np.zeros(tau.shape)), 1e-300)
    inv_nu = np.zeros(tau.shape)
    best = np.zeros(tau.shape)
    alpha = np.zeros(tau.shape, dtype=int)
    for term, value in contrib.items():
        nu = _term_edf(term, axis_terms[term], tau, ms, n_samples)
        with np.errstate(invalid='ignore', divide='ignore'):
            inv_nu += np.where(np.isfinite(nu), (value / total) / nu, 0.0)
        if not TERMS[term].deterministic:
            dom = value > best
            alpha = np.where(dom, TERMS[term].alpha_at(tau, axis_terms[term]), alpha)
            best = np.maximum(best, value)
    # a purely deterministic curve still has rounding-level scatter: cap the EDF
    nu = 1.0 / np.maximum(inv_nu, 1e-9)
    center = 0.5 * (np.log(total) + log_bias(nu))
    sd = 0.5 * log_sd(nu)
    return Band(tau, total, nu, alpha, center, sd)


def measured_band(measured, j):
    """
    Band of column ``j`` of a measured curve from its own EDF (only to start a fit).

    Centred on the measured ln(adev) less the chi-square log bias, with the spread its EDF
    implies: the first pass of a fit, before a model gives its own band.
    """
    nu = np.maximum(measured.edf[:, j], 1.0)
    center = np.log(measured.adev[:, j]) + 0.5 * log_bias(nu)
    return Band(measured.tau, measured.avar[:, j], nu, measured.alpha[:, j], center,
                0.5 * log_sd(nu))


def pool_simulations(band, sims):
    """Pool the analytic spread with simulated ln(adev) runs (K, T) about the analytic centre."""
    sims = np.atleast_2d(sims)
    k = sims.shape[0]
    dev2 = np.sum((sims - band.center) ** 2, axis=0)
    sd = np.sqrt((PRIOR_WEIGHT * band.sd ** 2 + dev2) / (PRIOR_WEIGHT + k))
    return Band(band.tau, band.avar, band.edf, band.alpha, band.center, sd, sims)


@dataclass
class Gap:
    """
    Model-vs-data gap of one axis.

    ``z`` per averaging time (units of the spread), ``value`` = sqrt(mean z^2) (about 1 when
    consistent), ``t_eff`` effective independent averaging times, ``p_value`` of
    ``value^2 t_eff`` under chi-square(t_eff), ``threshold`` the largest ``value`` still called
    consistent at the 1 - ``ALPHA`` level, ``tau_range`` the band where the data leave the model
    (s, or None).
    """

    z: np.ndarray
    value: float
    t_eff: float
    p_value: float
    threshold: float
    consistent: bool
    tau_range: tuple = None
    peak_tau: float = math.nan


def _smooth(z):
    if z.size < 3:
        return z.copy()
    padded = np.concatenate([[z[0]], z, [z[-1]]])
    return 0.25 * padded[:-2] + 0.5 * padded[1:-1] + 0.25 * padded[2:]


def excursion_band(tau, z, level=2.0):
    """
    Contiguous band of averaging times around the largest smoothed excursion |z| > level.

    Returns ``((tau_lo, tau_hi), tau_peak)``; the band is None when nothing exceeds ``level``.
    """
    zs = np.abs(_smooth(z))
    k = int(np.argmax(zs))
    if zs[k] <= level:
        return None, float(tau[k])
    lo = k
    while lo > 0 and zs[lo - 1] > level:
        lo -= 1
    hi = k
    while hi < zs.size - 1 and zs[hi + 1] > level:
        hi += 1
    return (float(tau[lo]), float(tau[hi])), float(tau[k])


def measure_gap(y, band, alpha=ALPHA):
    """Gap of measured ln(adev) ``y`` against a :class:`Band`."""
    z = (y - band.center) / band.sd
    value = float(np.sqrt(np.mean(z * z)))
    t_eff = band.effective_count()
    p = float(chi2.sf(value * value * t_eff, t_eff))
    threshold = float(math.sqrt(chi2.ppf(1.0 - alpha, t_eff) / t_eff))
    tau_range, peak = excursion_band(band.tau, z)
    return Gap(z, value, t_eff, p, threshold, p >= alpha, tau_range, peak)
