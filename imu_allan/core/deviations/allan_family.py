"""
Allan and Hadamard deviations, non-overlapping and overlapping: adev, oadev, hdev, ohdev.

All estimators take the phase ``x`` (A, N) in sample units (x_k = y_0 + ... + y_{k-1}, the
de-meaned rate integrated with tau0 = 1: tau0 cancels between the phase and tau) and return
the variance (T, A) in the rate's units squared, for averaging factors m (tau = m tau0).

- AVAR, non-overlapping (NIST SP1065 eq 7), stride m:
  sigma^2(tau) = sum_k (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 m^2 M), k = 0, m, 2m, ...
- OAVAR, overlapping (SP1065 eq 11): the same with stride 1, M = N - 2m terms.
- HVAR, Hadamard (SP1065 eq 18), stride m:
  sigma^2(tau) = sum_k (x_{k+3m} - 3 x_{k+2m} + 3 x_{k+m} - x_k)^2 / (6 m^2 M).
- OHVAR, overlapping Hadamard (SP1065 eq 20): stride 1, M = N - 3m terms.

EDF: Greenhall & Riley 2004 with d = 2 (Allan) or 3 (Hadamard), F = m, S = 1 or m
(:func:`imu_allan.core.allan.edf.edf_greenhall`); no bias correction (Stable32 applies none).
"""

import numpy as np

#: kind -> (difference order d, overlapping, normalisation of the squared difference)
SPEC = {'adev': (2, False, 2.0), 'oadev': (2, True, 2.0),
        'hdev': (3, False, 6.0), 'ohdev': (3, True, 6.0)}

#: Binomial coefficients of the d-th difference, x_{k+dm} first.
_COEF = {2: (1.0, -2.0, 1.0), 3: (1.0, -3.0, 3.0, -1.0)}


def variance_reference(kind, x, ms):
    """
    Variance of ``kind`` (adev, oadev, hdev, ohdev): the plain numpy definition, the oracle.

    Returns (T, A); nan where the record holds no complete difference.
    """
    d, overlapping, norm = SPEC[kind]
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        count = n_phase - d * m  # starting points k with k + d m <= N - 1
        if count < 1:
            continue
        stride = 1 if overlapping else m
        diff = sum(c * x[:, (d - j) * m:(d - j) * m + count:stride]
                   for j, c in enumerate(_COEF[d]))
        out[i] = np.sum(diff * diff, axis=1) / (norm * m * m * diff.shape[1])
    return out


def terms(kind, n_phase, m):
    """Count the differences behind the estimate at factor ``m`` (Stable32's '#')."""
    d, overlapping, _ = SPEC[kind]
    count = n_phase - d * m
    if count < 1:
        return 0
    return count if overlapping else (count - 1) // m + 1


def edf_args(kind):
    """(d, overlapping, modified) of :func:`~..allan.edf.edf_greenhall` for ``kind``."""
    d, overlapping, _ = SPEC[kind]
    return d, overlapping, False
