"""
Warm-up: a bias that settles exponentially at the start of a record.

A MEMS IMU switched on drifts while it warms: b(t) = c + a exp(-t / T), T of a few minutes.
Left in, the settling raises the Allan deviation at long averaging times (it looks like a rate
random walk or a ramp).  :func:`find_warmup` fits that curve to the block means of the first
part of the record and calls it a warm-up only when its amplitude stands out of the noise
that the same record shows at that time scale: |a| > :data:`Z_MIN` x sigma_A(T), the Allan
deviation at tau = T measured on the rest of the record (non-overlapping, from the same block
means).  That comparison is what keeps flicker and random-walk wander, whose excursions over T
are a few sigma_A(T), from being taken for a warm-up.

``warmup_s`` = 3 T (the bias is then within 5 % of its initial offset from the final value),
the median over the axes where a warm-up is found.

Units: samples SI (rad/s, m/s^2), times in s from the first sample.
"""

import math

import numpy as np

#: Amplitude over sigma_A(T) needed to call a settling curve a warm-up.  Static simulated
#: records (flicker + random walk, test/core/test_warmup.py) gave at most 12 in 144 axes.
Z_MIN = 15.0
#: Settling time constants tried, s (log-spaced), and the block of the means, s.
T_MIN_S, T_MAX_S, N_T = 30.0, 1200.0, 40
#: Longest start fitted, s (and at most half the record): 3 x T_MAX_S.
SPAN_MAX_S = 3600.0
BLOCK_S = 5.0
#: Shortest record checked, s: the settling (3 T) must be followed by as much settled data.
MIN_RECORD_S = 1200.0
#: Fewest clusters behind a sigma_A (fewer: a noisy denominator).
MIN_CLUSTERS = 8


def _block_means(data, rate_hz, block_s):
    block = max(int(round(block_s * rate_hz)), 1)
    n = data.shape[0] // block
    return data[:n * block].reshape(n, block, -1).mean(axis=1), block / rate_hz


def _nonoverlapping_adev(means, factor):
    """Allan deviation of block means at ``factor`` blocks (non-overlapping, NIST eq. 7)."""
    n = means.shape[0] // factor
    if n < 3:
        return np.full(means.shape[1], np.nan)
    y = means[:n * factor].reshape(n, factor, -1).mean(axis=1)
    return np.sqrt(0.5 * np.mean(np.diff(y, axis=0) ** 2, axis=0))


def _sigma_at(means, factor):
    """
    sigma_A at ``factor`` blocks, from at least MIN_CLUSTERS clusters.

    Beyond that, extrapolated from the longest such factor with the random-walk slope +1/2
    (the steepest of the usual terms: conservative, a larger sigma).
    """
    longest = means.shape[0] // MIN_CLUSTERS
    if longest < 1:
        return math.nan
    if factor <= longest:
        return float(_nonoverlapping_adev(means, factor)[0])
    return float(_nonoverlapping_adev(means, longest)[0]) * math.sqrt(factor / longest)


def fit_settling(means, dt, t_grid):
    """
    Best exponential c + a exp(-t/T) over ``t_grid`` for each column of block means.

    Returns ``(T, a, c)`` per column (least squares; T from the grid).
    """
    t = (np.arange(means.shape[0]) + 0.5) * dt
    best_sse = np.full(means.shape[1], np.inf)
    out_t, out_a, out_c = (np.full(means.shape[1], np.nan) for _ in range(3))
    for tc in t_grid:
        x = np.column_stack((np.ones_like(t), np.exp(-t / tc)))
        coef, *_ = np.linalg.lstsq(x, means, rcond=None)
        sse = np.sum((means - x @ coef) ** 2, axis=0)
        better = sse < best_sse
        best_sse[better] = sse[better]
        out_t[better], out_a[better], out_c[better] = tc, coef[1, better], coef[0, better]
    return out_t, out_a, out_c


def find_warmup(data, rate_hz, axes=None):
    """
    Return ``(warmup_s, details)``: when the start's settling bias is over (0: none).

    ``details``: per axis ``{'tau_s', 'amplitude', 'z'}`` of the best settling fit (SI),
    ``'warmup'`` True where it counts.  The record's first half (at most SPAN_MAX_S) is fitted.
    """
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    axes = axes or [f'axis{j}' for j in range(data.shape[1])]
    duration = data.shape[0] / rate_hz
    if duration < MIN_RECORD_S:
        return 0.0, {}
    span = min(duration / 2.0, SPAN_MAX_S)
    block_s = max(BLOCK_S, 1.0 / rate_hz)
    means, dt = _block_means(data[:int(span * rate_hz)], rate_hz, block_s)
    t_max = min(T_MAX_S, span / 3.0)
    if t_max <= T_MIN_S:
        return 0.0, {}
    tc, amp, _ = fit_settling(means, dt, np.geomspace(T_MIN_S, t_max, N_T))
    rest, _ = _block_means(data[int(span * rate_hz):], rate_hz, block_s)
    details, warm = {}, []
    for j, axis in enumerate(axes):
        sigma = _sigma_at(rest[:, j:j + 1], max(int(round(tc[j] / dt)), 1))
        z = abs(amp[j]) / sigma if sigma > 0 else math.inf
        found = bool(z > Z_MIN and tc[j] < t_max)  # at the grid's end: not settled yet
        details[axis] = {'tau_s': float(tc[j]), 'amplitude': float(amp[j]), 'z': float(z),
                         'warmup': found}
        if found:
            warm.append(3.0 * float(tc[j]))
    # One warm-up for the IMU (it is thermal): the median over the axes that show it (the
    # largest would pick the axis whose wander lengthened its fit most).
    return (float(np.median(warm)) if warm else 0.0), details


def warmup_sentence(warmup_s):
    """Return the console line: 'first 14 min left out: the bias was settling' (or '')."""
    if not warmup_s:
        return ''
    return f'first {warmup_s / 60.0:.0f} min left out: the bias was settling'
