"""
Averaging factors per deviation kind: Stable32's stop ratios, explicit taus rounded to m.

Stable32 stops a run at the largest averaging factor n / ratio (Riley, "The evolution of
stability analysis", table III; allantools ``tau_generator``): adev 5, oadev 4, mdev and tdev
4, hdev 5, ohdev 4, totdev 2, mtotdev and htotdev 3, theo1 1 (:attr:`.kinds.Kind.stop_ratio`).
``oadev`` keeps the package's own guard instead (at least ``min_clusters`` non-overlapping
clusters at the longest tau, :func:`imu_allan.core.allan.estimate.tau_grid`), so that it stays the
grid of ``allan_deviation``.  Theo1 uses even m only and tau = 0.75 m tau0.
"""

import numpy as np

from .kinds import KIND
from ..allan.estimate import log_grid, tau_grid

STOP_RATIO = {name: kind.stop_ratio for name, kind in KIND.items()}
KINDS = tuple(KIND)


def tau_factor(kind):
    """Tau / (m tau0): 0.75 for theo1, else 1."""
    return KIND[kind].tau_factor


def default_ms(kind, n_samples, points_per_decade, min_clusters):
    """Log-spaced averaging factors of ``kind`` for ``n_samples`` rate samples."""
    spec = KIND[kind]
    if spec.allan_grid:
        return tau_grid(n_samples, points_per_decade, min_clusters)
    stop = min(n_samples // spec.stop_ratio, n_samples - 1)
    ms = log_grid(stop, points_per_decade)
    if spec.m_step > 1:
        ms = np.unique(spec.m_step * np.maximum(ms // spec.m_step, 1))
        ms = ms[ms <= stop]
    return ms


def ms_from_taus(kind, taus, rate_hz):
    """Averaging factors for explicit taus (s): whole multiples of the kind's step (theo1 2)."""
    spec = KIND[kind]
    tau = np.atleast_1d(np.asarray(taus, dtype=float))
    step = spec.m_step
    return step * np.round(tau * rate_hz / (step * spec.tau_factor)).astype(np.int64)
