"""
Averaging factors per deviation kind: Stable32's stop ratios, explicit taus rounded to m.

Stable32 stops a run at the largest averaging factor n / ratio (Riley, "The evolution of
stability analysis", table III; allantools ``tau_generator``): adev 5, oadev 4, mdev and tdev
4, hdev 5, ohdev 4, totdev 2, mtotdev and htotdev 3, theo1 1.  ``oadev`` keeps the package's
own guard instead (at least ``min_clusters`` non-overlapping clusters at the longest tau,
:func:`imu_allan.core.allan.tau_grid`), so that it stays the grid of ``allan_deviation``.
Theo1 uses even m only and tau = 0.75 m tau0.
"""

import numpy as np

from ..allan import log_grid, tau_grid

STOP_RATIO = {'adev': 5, 'oadev': 4, 'mdev': 4, 'tdev': 4, 'hdev': 5, 'ohdev': 4,
              'totdev': 2, 'mtotdev': 3, 'htotdev': 3, 'theo1': 1}
KINDS = tuple(STOP_RATIO)


def tau_factor(kind):
    """Tau / (m tau0): 0.75 for theo1, else 1."""
    return 0.75 if kind == 'theo1' else 1.0


def default_ms(kind, n_samples, points_per_decade, min_clusters):
    """Log-spaced averaging factors of ``kind`` for ``n_samples`` rate samples."""
    if kind == 'oadev':
        return tau_grid(n_samples, points_per_decade, min_clusters)
    stop = n_samples // STOP_RATIO[kind]
    if kind == 'theo1':
        stop = min(stop, n_samples - 1)
        ms = log_grid(stop, points_per_decade)
        ms = np.unique(2 * np.maximum(ms // 2, 1))
        return ms[ms <= stop]
    return log_grid(stop, points_per_decade)


def ms_from_taus(kind, taus, rate_hz):
    """Averaging factors for explicit taus (s): whole m (even m for theo1, tau = 0.75 m)."""
    tau = np.atleast_1d(np.asarray(taus, dtype=float))
    if kind == 'theo1':
        return 2 * np.round(tau * rate_hz / (2.0 * tau_factor(kind))).astype(np.int64)
    return np.round(tau * rate_hz).astype(np.int64)
