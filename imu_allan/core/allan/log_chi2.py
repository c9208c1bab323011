"""
The logarithm of a chi-square distributed variance estimate: its bias and its spread.

An AVAR estimate with nu equivalent degrees of freedom is AVAR chi^2_nu / nu (SP1065 eq. 45), so
ln(estimate / AVAR) has mean psi(nu / 2) - ln(nu / 2) and variance psi'(nu / 2) (psi: digamma,
psi': trigamma; the moments of the log of a gamma variable).  The logarithm makes even the
few-EDF estimates at long averaging times nearly normal and, unlike the estimate itself, gives
a spread that does not depend on the AVAR it scatters about: the noise fit works in this
domain (:mod:`imu_allan.core.fit.axis`), and so do the adequacy test and the discrepancy band.
"""

import numpy as np

from ..scipy_compiled import function

_digamma = function('special', '_special_ufuncs', 'psi')


def trigamma(x):
    """
    psi'(x) for x > 0 (array): the variance of ln(chi^2_nu / nu) at x = nu / 2.

    Recurrence psi'(x) = psi'(x + 1) + 1 / x^2 up to x >= 10, then the asymptotic series
    1/x + 1/(2x^2) + 1/(6x^3) - 1/(30x^5) + 1/(42x^7) - 1/(30x^9) (Abramowitz & Stegun 6.4.12;
    within 1e-11 of scipy's polygamma(1, x), whose module costs 0.3 s to import).
    """
    x = np.array(x, dtype=float)
    out = np.zeros_like(x)
    small = x < 10.0
    while np.any(small):
        out[small] += 1.0 / x[small] ** 2
        x[small] += 1.0
        small = x < 10.0
    w = 1.0 / x
    w2 = w * w
    return out + w + w2 / 2.0 + w * w2 * (1.0 / 6.0 - w2 * (1.0 / 30.0 - w2 * (
        1.0 / 42.0 - w2 / 30.0)))


def log_bias(edf):
    """Return the mean of ln(chi^2_nu / nu) for ``edf`` nu (array): psi(nu/2) - ln(nu/2)."""
    half = 0.5 * np.asarray(edf, dtype=float)
    return _digamma(half) - np.log(half)


def log_sd(edf):
    """Return the standard deviation of ln(chi^2_nu / nu) for ``edf`` nu: sqrt(psi'(nu/2))."""
    return np.sqrt(trigamma(0.5 * np.asarray(edf, dtype=float)))
