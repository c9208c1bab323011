"""
One factor from several recordings: pooled, or as a power of the sample rate.

Each recording gives ln(factor) with a standard error (:class:`.evidence.LogEstimate`).  With
one sample rate the estimates are pooled by inverse variance.  With several rates,
ln factor = a + p ln(f / 1 Hz) is fitted by weighted least squares: ``p`` is the *rate
exponent* (-1/2 when a per-sample value is read as a density, +1/2 the reverse, -1 for a
variance) and exp(a) the factor at 1 Hz, where a per-sample value equals the density it was
mistaken for.  Scatter beyond the stated errors (reduced chi-square above 1, with at least three
degrees of freedom to estimate it) widens every interval by its square root.

Intervals are symmetric in ln factor: 68.3 % (+-1 se) and 95 % (+-1.96 se).
"""

from dataclasses import dataclass, field
import math

import numpy as np
from scipy.stats import norm

#: Rates closer than this ratio count as one rate.
SAME_RATE = 1.02


@dataclass
class Pooled:
    """
    A factor from several recordings.

    ``log``/``se``: ln factor (pooled; at 1 Hz when ``exponent`` is set) and its error;
    ``exponent``/``exponent_se`` the fitted rate exponent (None with one rate);
    ``z``: |ln factor| / se of the pooled factor; ``z_exponent``: |exponent| / se;
    ``per_rate``: [{rate_hz, log, se, runs}]; ``scaled``: True when the factor is reported at
    1 Hz with its exponent.
    """

    log: float
    se: float
    z: float
    exponent: float = None
    exponent_se: float = None
    z_exponent: float = 0.0
    per_rate: list = field(default_factory=list)
    scaled: bool = False
    n: int = 0

    def factor(self):
        """Return the pooled value, at 1 Hz when it scales with the rate."""
        return math.exp(self.log)

    def interval(self, z=1.0):
        """Interval of the factor at +-z standard errors."""
        return [math.exp(self.log - z * self.se), math.exp(self.log + z * self.se)]

    def exponent_interval(self, z=1.0):
        """Interval of the rate exponent, or None."""
        if self.exponent is None:
            return None
        return [self.exponent - z * self.exponent_se, self.exponent + z * self.exponent_se]

    def at_rate(self, rate_hz):
        """Return the factor at one sample rate (Hz)."""
        if self.scaled:
            return math.exp(self.log + self.exponent * math.log(rate_hz))
        return math.exp(self.log)


def z_critical(alpha, n_tests):
    """Two-sided critical z of a family of ``n_tests`` tests at level ``alpha`` (Bonferroni)."""
    return float(norm.isf(alpha / (2.0 * max(n_tests, 1))))


def _rate_groups(estimates):
    """Estimates grouped by sample rate (rates within :data:`SAME_RATE` are one)."""
    groups = []
    for e in sorted(estimates, key=lambda e: e.rate_hz):
        if groups and e.rate_hz / groups[-1][0].rate_hz < SAME_RATE:
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def _weighted_mean(estimates):
    """Inverse-variance mean of the logs and its error (widened by excess scatter)."""
    logs = np.array([e.log for e in estimates])
    w = 1.0 / np.array([e.se for e in estimates]) ** 2
    mean = float(np.sum(w * logs) / np.sum(w))
    se = math.sqrt(1.0 / float(np.sum(w)))
    chi2 = float(np.sum(w * (logs - mean) ** 2))
    dof = len(estimates) - 1
    if dof >= 3 and chi2 / dof > 1.0:
        se *= math.sqrt(chi2 / dof)
    return mean, se


def pool(estimates, z_crit):
    """
    Combine :class:`.evidence.LogEstimate` s into a :class:`Pooled` (None if none is usable).

    With two or more rates the power law is fitted; the factor is reported at 1 Hz with its
    exponent when the exponent differs from 0 by more than ``z_crit`` errors, else pooled.
    """
    usable = [e for e in estimates if e.usable]
    if not usable:
        return None
    mean, se = _weighted_mean(usable)
    per_rate = []
    for group in _rate_groups(usable):
        m, s = _weighted_mean(group)
        per_rate.append({'rate_hz': float(np.exp(np.mean(np.log([e.rate_hz for e in group])))),
                         'log': m, 'se': s, 'runs': len(group)})
    out = Pooled(mean, se, abs(mean) / se, per_rate=per_rate, n=len(usable))
    if len(per_rate) < 2:
        return out
    logs = np.array([e.log for e in usable])
    x = np.log([e.rate_hz for e in usable])
    w = 1.0 / np.array([e.se for e in usable]) ** 2
    design = np.column_stack([np.ones_like(x), x])
    info = design.T @ (design * w[:, None])
    cov = np.linalg.inv(info)
    coef = cov @ (design.T @ (w * logs))
    resid = logs - design @ coef
    dof = len(usable) - 2
    red = float(np.sum(w * resid ** 2)) / dof if dof > 0 else 1.0
    if dof >= 3 and red > 1.0:
        cov = cov * red
    out.exponent = float(coef[1])
    out.exponent_se = math.sqrt(float(cov[1, 1]))
    out.z_exponent = abs(out.exponent) / out.exponent_se
    if out.z_exponent > z_crit:
        out.log, out.se = float(coef[0]), math.sqrt(float(cov[0, 0]))
        out.z = abs(out.log) / out.se
        out.scaled = True
    return out
