"""
Modified Allan deviation and time deviation: mdev, tdev.

With the phase ``x`` (A, N) in sample units (see :mod:`.allan_family`) and tau = m tau0,
NIST SP1065 eq 14:

    Mod sigma^2(tau) = 1 / (2 m^2 tau^2 (N - 3m + 1))
                       sum_{j=0}^{N-3m} [ sum_{i=j}^{j+m-1} (x_{i+2m} - 2 x_{i+m} + x_i) ]^2,

the Allan variance of the phase averaged over m samples: it falls as tau^-3 for white PM
(quantization) and tau^-2 for flicker PM where the Allan variance falls as tau^-2 for both,
so MDEV splits quantization from white noise.  TDEV (SP1065 eq 15): sigma_x(tau) = tau /
sqrt(3) Mod sigma_y(tau), in the rate's units times seconds (rad for a gyro).

EDF: Greenhall & Riley 2004, d = 2, F = 1 (modified), S = m (overlapping).  No bias
correction (Stable32 applies none).
"""

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view


def variance_reference(x, ms):
    """MVAR (T, A) by the literal double sum of SP1065 eq 14 (the oracle; O(N m) per m)."""
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        count = n_phase - 3 * m + 1
        if count < 1:
            continue
        d2 = x[:, 2 * m:] - 2.0 * x[:, m:n_phase - m] + x[:, :n_phase - 2 * m]
        inner = sliding_window_view(d2, m, axis=1)[:, :count].sum(axis=2)
        out[i] = np.sum(inner * inner, axis=1) / (2.0 * m ** 4 * count)
    return out


def variance_fast(x, ms):
    """
    MVAR like :func:`variance_reference` in O(N) per m.

    The inner sums of consecutive j differ by one third difference,
    v_{j+1} = v_j + x_{j+3m} - 3 x_{j+2m} + 3 x_{j+m} - x_j (Stable32's and allantools'
    recursion), so they are a cumulative sum of third differences: no moving-window sums of
    the phase, whose rounding would grow with the phase.
    """
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        count = n_phase - 3 * m + 1
        if count < 1:
            continue
        first = np.sum(x[:, 2 * m:3 * m] - 2.0 * x[:, m:2 * m] + x[:, :m], axis=1)
        v = np.empty((x.shape[0], count))
        v[:, 0] = first
        if count > 1:
            step = (x[:, 3 * m:] - 3.0 * x[:, 2 * m:n_phase - m] + 3.0 * x[:, m:n_phase - 2 * m]
                    - x[:, :n_phase - 3 * m])
            np.cumsum(step, axis=1, out=v[:, 1:])
            v[:, 1:] += first[:, None]
        out[i] = np.sum(v * v, axis=1) / (2.0 * m ** 4 * count)
    return out


def terms(n_phase, m):
    """Count the squared inner sums behind the estimate (Stable32's '#'): N - 3m + 1."""
    return max(n_phase - 3 * m + 1, 0)


def tdev_scale(tau):
    """TDEV / MDEV = tau / sqrt(3) (SP1065 eq 15), tau in s."""
    return np.asarray(tau, dtype=float) / np.sqrt(3.0)
