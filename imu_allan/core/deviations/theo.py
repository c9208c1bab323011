"""
Theo1 deviation: theo1, at tau = 0.75 m tau0 with m even (as Stable32).

Phase ``x`` (A, N) in sample units as in :mod:`.allan_family`.  NIST SP1065 eq 30:

    Theo1(m, tau0, N) = 1 / (0.75 (N - m) (m tau0)^2)
        sum_{i=1}^{N-m} sum_{delta=0}^{m/2-1} 1 / (m/2 - delta)
            [(x_i - x_{i-delta+m/2}) + (x_{i+m} - x_{i+delta+m/2})]^2,

an unbiased estimator of the Allan variance at tau = 0.75 m tau0 for white FM that reaches
tau = 0.75 T (the Allan variance stops at T/2).  For other noise types its expectation is
AVAR / b with b(alpha, m) = a + b' / (0.75 m)^c (Howe and Tasset, "Theo1: characterization of
very long-term frequency stability", EFTF 2004, table 1; the bias Stable32 removes when the
noise type is known): a, b', c = 0.09, 0.74, 0.40 white PM; 0.14, 0.82, 0.30 flicker PM;
1, 0, 0 white FM; 1.87, -1.05, 0.79 flicker FM; 2.70, -1.53, 0.85 random-walk FM.  The
printed value is Theo1 x b.

EDF (Howe and Peppler, "Estimation of very long-term frequency stability using a
special-purpose statistic", 2003; SP1065 table 10), r = 0.75 m, N phase points:
white PM   0.86 (N + 1)(N - 4r/3) / (N - r) x r / (r + 1.14),
flicker PM (4.798 N^2 - 6.374 N r + 12.387 r) / (sqrt(r + 36.6) (N - r)) x r / (r + 0.3),
white FM   ((4.1 N + 0.8) / r - (3.1 N + 6.5) / N) x r^1.5 / (r^1.5 + 5.2),
flicker FM (2 N^2 - 1.3 N r - 3.5 r) / (N r) x r^3 / (r^3 + 2.3),
RW FM      (4.4 N - 2) / (2.9 r) x ((4.4 N - 1)^2 - 8.6 r (4.4 N - 1) + 11.4 r^2)
           / (4.4 N - 3)^2.
"""

import math

import numpy as np

#: Theo1 bias b = a + b' / (0.75 m)^c by alpha (AVAR = b Theo1).
BIAS = {2: (0.09, 0.74, 0.40), 1: (0.14, 0.82, 0.30), 0: (1.0, 0.0, 0.0),
        -1: (1.87, -1.05, 0.79), -2: (2.70, -1.53, 0.85)}


def theo1_reference(x, ms):
    """Theo1 variance (T, A), uncorrected, by the literal double sum (the oracle)."""
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for t, m in enumerate(ms):
        m = int(m)
        if m % 2 or m < 2 or m > n_phase - 1:
            continue
        h = m // 2
        count = n_phase - m
        total = np.zeros(x.shape[0])
        i = np.arange(count)
        for delta in range(h):
            a = (x[:, i] - x[:, i - delta + h] + x[:, i + m] - x[:, i + delta + h])
            total += np.sum(a * a, axis=1) / (h - delta)
        out[t] = total / (0.75 * count * m * m)
    return out


def theo1_fast(x, ms, strides=None):
    """
    Theo1 like :func:`theo1_reference`, the inner sum as one vectorized pass per delta.

    The summand is (u_i - x_{i+h-delta} - x_{i+h+delta})^2 with u_i = x_i + x_{i+m} and
    h = m/2, so u is formed once per m and each delta costs one pass over N - m values (O(N m)
    per m in all, like the definition, without its index arrays).  ``strides`` (T,): only every
    stride-th i enters the average (:mod:`.total_kernel`'s thinned estimate; 1: exact).
    """
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for t, m in enumerate(ms):
        m = int(m)
        if m % 2 or m < 2 or m > n_phase - 1:
            continue
        h = m // 2
        count = n_phase - m
        s = 1 if strides is None else int(strides[t])
        u = x[:, :count:s] + x[:, m:m + count:s]
        total = np.zeros(x.shape[0])
        for delta in range(h):
            a = (u - x[:, h - delta:h - delta + count:s]
                 - x[:, h + delta:h + delta + count:s])
            total += np.einsum('ij,ij->i', a, a) / (h - delta)
        out[t] = total / (0.75 * u.shape[1] * m * m)
    return out


def terms(n_phase, m):
    """Stable32's '#' for Theo1: (N - m) m / 2 summands."""
    return max(n_phase - m, 0) * (m // 2)


def bias(alpha, m):
    """Theo1 bias b (AVAR = b x Theo1) for noise ``alpha`` at factor ``m``; 1 if unknown."""
    a, b, c = BIAS.get(int(alpha), (1.0, 0.0, 0.0))
    return a + b / (0.75 * m) ** c


def edf(alpha, m, n_phase):
    """Theo1 EDF (module docstring); alpha outside +2 .. -2 is clipped."""
    n = float(n_phase)
    r = 0.75 * m
    alpha = max(min(int(alpha), 2), -2)
    if alpha == 2:
        return 0.86 * (n + 1) * (n - 4 * r / 3) / (n - r) * r / (r + 1.14)
    if alpha == 1:
        return ((4.798 * n * n - 6.374 * n * r + 12.387 * r) / (math.sqrt(r + 36.6) * (n - r))
                * r / (r + 0.3))
    if alpha == 0:
        return ((4.1 * n + 0.8) / r - (3.1 * n + 6.5) / n) * r ** 1.5 / (r ** 1.5 + 5.2)
    if alpha == -1:
        return (2 * n * n - 1.3 * n * r - 3.5 * r) / (n * r) * r ** 3 / (r ** 3 + 2.3)
    k = 4.4 * n
    return (k - 2) / (2.9 * r) * ((k - 1) ** 2 - 8.6 * r * (k - 1) + 11.4 * r * r) / (k - 3) ** 2
