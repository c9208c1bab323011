"""
Total deviations: totdev, mtotdev, htotdev.

Phase ``x`` (A, N) in sample units as in :mod:`.allan_family`; tau = m tau0.

- TOTVAR (NIST SP1065 eq 25): the phase is extended by odd reflection at both ends,
  x*_{1-j} = 2 x_1 - x_{1+j} and x*_{N+j} = 2 x_N - x_{N-j} (j = 1 .. N - 2), and
  Tot sigma^2(tau) = sum_{i=2}^{N-1} (x*_{i-m} - 2 x*_i + x*_{i+m})^2 / (2 tau^2 (N - 2)).
  Bias (Howe, "Total variance explained", 1999, table 1): E[TOTVAR] = AVAR (1 - a tau / T)
  with a = 0 white FM, 1 / (3 ln 2) flicker FM, 3/4 random-walk FM, T = N tau0; the printed
  value is divided by (1 - a tau / T).
- MTOTVAR (SP1065 eq 27): for each of the N - 3m + 1 subsequences of 3m phase points, a line
  through the means of its two halves is removed, the result is extended by even reflection
  to 9m points, and the 6m overlapping second differences of m-point averages are squared
  and averaged; Mod Tot sigma^2 = sum over subsequences / (2 m^2 tau^2 (N - 3m + 1)).
  Stable32 applies no bias correction to it (its tables agree with the uncorrected value).
- HTOTVAR (SP1065 eq 29; Howe et al., "A total estimator of the Hadamard function used for
  GPS operations", PTTI 2000): the same construction on the N - 1 rate samples (subsequences
  of 3m rates, line removed, even reflection to 9m, 6m second differences of the rate's
  m-averages, i.e. Hadamard differences, squared and divided by 6); at m = 1 the overlapping
  Hadamard variance (as Stable32).  Bias (same paper, table 2): E[HTOTVAR] = HVAR (1 + a),
  a = -0.005 white FM, -0.149 flicker FM, -0.229 random-walk FM, -0.283 flicker-walk FM,
  -0.321 random-run FM; divided out for m > 1.

EDF, with N the phase points and the noise alpha of the row:

- TOTVAR: SP1065 table 7, b N/m - c (Stable32 the same).
- MTOTVAR: SP1065 table 8, b N/m - c, from m = 16; the modified Allan variance's Greenhall EDF
  below.  Stable32 (1.53, 1.60) uses other coefficients from m = 10 on (its printed bounds on
  PHASE.DAT, N = 1001, and on AllanToolkit's Sr87 tables, N = 1253, give b, c = 1.331, 1.90
  white FM; 1.731, 2.99 flicker PM; 0.920, 0.76 flicker FM: :data:`MTOTVAR_EDF_STABLE32`).  They
  are published nowhere we found and overstate the EDF: a Monte Carlo of white FM (N = 1001,
  3000 records) gives 64.7, 31.7, 14.8, 6.0 at m = 16, 32, 64, 128, table 8 67.6, 33.2, 16.0,
  7.4, Stable32's 81.3, 39.7, 18.9, 8.5 (intervals too narrow); the package keeps table 8.
- HTOTVAR: (N/m) / (b0 + b1 m/N) from m = 16 with the coefficients of Howe, Beard, Greenhall and
  Riley (PTTI 2000, table 1; as copied in AllanToolkit's tables.yml) for white, flicker and
  random-walk FM: Stable32 uses them (its bounds give them back to 4 digits for white and
  flicker FM on both data sets above) and a Monte Carlo (N = 1001, 2000-3000 records, m = 16,
  32, 64) agrees within its 5 % scatter (white FM 108, 25.1 at m = 16, 64; flicker 72, 38, 17;
  random walk 64, 33, 15), where SP1065 table 9's (0.546, 1.02; 0.650, 0.940; 0.767, 0.726)
  give up to 1.3 x too many for flicker and random-walk FM.  For flicker walk and random run FM
  the paper's values as copied there (2.554, 0.974; 3.149, 1.276) give 2.5 x fewer than the
  Monte Carlo (62, 31, 13 and 51, 24, 10), SP1065's (0.900, 0.7; 0.978, 0.55) 1.1 x and 1.3 x
  more; the package keeps SP1065's there (Stable32's bounds for these noises not checked).
  Below m = 16 Stable32 uses an EDF it does not publish (on PHASE.DAT 668, 571, 348, 184 at
  m = 1, 2, 4, 8, white FM; no Greenhall-Riley variant of any d, F, S, alpha gives them back
  to better than 1 %); the package uses the overlapping Hadamard variance's Greenhall EDF there
  (HTOTVAR is OHVAR at m = 1; 452, 257, 140 at m = 2, 4, 8: conservative against the Monte
  Carlo's 604, 400, 210).  No HTOTVAR EDF is published for phase noise (alpha > 0): the
  Hadamard variance's there too.
"""

import math

import numpy as np

#: TOTVAR bias coefficient a (E[TOTVAR] = AVAR (1 - a tau/T)), by alpha.
TOTVAR_BIAS = {0: 0.0, -1: 1.0 / (3.0 * math.log(2.0)), -2: 0.75}
#: HTOTVAR bias a (E[HTOTVAR] = HVAR (1 + a)), by alpha.
HTOTVAR_BIAS = {0: -0.005, -1: -0.149, -2: -0.229, -3: -0.283, -4: -0.321}
#: SP1065 table 7: TOTVAR EDF b N/m - c, by alpha.
TOTVAR_EDF = {0: (1.50, 0.0), -1: (1.17, 0.22), -2: (0.93, 0.36)}
#: SP1065 table 8: MTOTVAR EDF b N/m - c, by alpha.
MTOTVAR_EDF = {2: (1.90, 2.1), 1: (1.20, 1.40), 0: (1.10, 1.2), -1: (0.85, 0.50),
               -2: (0.75, 0.31)}
#: Stable32's MTOTVAR EDF b N/m - c from m = 10, by alpha, recovered from its printed bounds
#: (module docstring; not used by the package: documented and tested against the tables).
MTOTVAR_EDF_STABLE32 = {1: (1.7307, 2.993), 0: (1.3305, 1.897), -1: (0.9197, 0.760)}
#: HTOTVAR EDF (N/m) / (b0 + b1 m/N), by alpha: Howe, Beard, Greenhall & Riley (PTTI 2000)
#: table 1 for alpha 0, -1, -2 (Stable32's; SP1065 table 9 prints other values), SP1065 table 9
#: for -3, -4 (module docstring).
HTOTVAR_EDF = {0: (0.559, 1.004), -1: (0.868, 1.140), -2: (0.938, 1.696), -3: (0.900, 0.7),
               -4: (0.978, 0.55)}


def reflect(x):
    """Return the doubly reflected phase x* of SP1065 eq 25, (A, 3N - 4), x in the middle."""
    n_phase = x.shape[1]
    left = 2.0 * x[:, :1] - x[:, 1:n_phase - 1][:, ::-1]
    right = 2.0 * x[:, -1:] - x[:, 1:n_phase - 1][:, ::-1]
    return np.concatenate([left, x, right], axis=1)


def totvar(x, ms):
    """TOTVAR (T, A), uncorrected, SP1065 eq 25 (O(N) per m)."""
    n_phase = x.shape[1]
    xs = reflect(x)
    mid = n_phase - 2  # index of x_1 (0-based x[0]) in x*
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        if m > n_phase - 2 or n_phase < 3:
            continue
        c = xs[:, mid + 1:mid + n_phase - 1]  # x*_i, i = 2 .. N-1
        lo = xs[:, mid + 1 - m:mid + n_phase - 1 - m]
        hi = xs[:, mid + 1 + m:mid + n_phase - 1 + m]
        d = lo - 2.0 * c + hi
        out[i] = np.sum(d * d, axis=1) / (2.0 * m * m * (n_phase - 2))
    return out


def _detrended_windows(z, m):
    """
    Windows of 3m consecutive values of ``z`` (A, L) with the half-mean line removed.

    Returns (A, W, 3m), W = L - 3m + 1.  The slope is the difference of the means of the first
    and last floor(3m/2) values over the distance between their centres (SP1065 eq 27).
    """
    from numpy.lib.stride_tricks import sliding_window_view
    win = sliding_window_view(z, 3 * m, axis=1)
    half = (3 * m) // 2
    dist = (3 * m + 1) // 2  # centres of the two halves are ceil(3m/2) apart
    slope = (win[..., 3 * m - half:].mean(axis=-1) - win[..., :half].mean(axis=-1)) / dist
    return win - slope[..., None] * np.arange(3 * m, dtype=float)


def _reflected_terms(w, m):
    """
    Mean square of 6m second differences of m-sums over reflected windows, over m^2.

    The reflection of each window ``w`` (..., 3m) is [flip(w), w, flip(w)] (9m points).

    On phase windows these are Allan differences of m-averaged phase (MTOTVAR); on rate
    windows, Hadamard differences (HTOTVAR).
    """
    ext = np.concatenate([w[..., ::-1], w, w[..., ::-1]], axis=-1)  # (..., 9m)
    c = np.concatenate([np.zeros(ext.shape[:-1] + (1,)), np.cumsum(ext, axis=-1)], axis=-1)
    sums = c[..., m:] - c[..., :-m]  # m-point sums starting at 0 .. 8m
    diff = sums[..., :6 * m] - 2.0 * sums[..., m:7 * m] + sums[..., 2 * m:8 * m]
    return np.mean(diff * diff, axis=-1) / (m * m)


def _chunks(count, m, budget=4_000_000):
    """Window ranges whose (9m + 1)-point extensions fit in ``budget`` floats."""
    step = max(1, budget // (9 * m + 1))
    return [(lo, min(lo + step, count)) for lo in range(0, count, step)]


def _window_sums(z, m):
    """Sum over every 3m-window start of ``z`` (A, L) of its reflected terms (A,), chunked."""
    total = np.zeros(z.shape[0])
    for lo, hi in _chunks(z.shape[1] - 3 * m + 1, m):
        w = _detrended_windows(z[:, lo:hi + 3 * m - 1], m)
        total += np.sum(_reflected_terms(w, m), axis=1)
    return total


def mtotvar(x, ms):
    """MTOTVAR (T, A), SP1065 eq 27, uncorrected (as Stable32); O(N m) per m."""
    n_phase = x.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        count = n_phase - 3 * m + 1
        if count >= 1:
            out[i] = _window_sums(x, m) / (2.0 * m * m * count)
    return out


def htotvar(x, ms):
    """HTOTVAR (T, A), SP1065 eq 29, uncorrected; OHVAR at m = 1; O(N m) per m."""
    from .allan_family import variance_reference
    y = np.diff(x, axis=1)
    n_rate = y.shape[1]
    out = np.full((len(ms), x.shape[0]), np.nan)
    for i, m in enumerate(ms):
        m = int(m)
        if m == 1:
            out[i] = variance_reference('ohdev', x, [1])[0]
            continue
        count = n_rate - 3 * m + 1
        if count >= 1:
            out[i] = _window_sums(y, m) / (6.0 * count)
    return out


def terms(kind, n_phase, m):
    """Stable32's '#': N - 2 (totdev), N - 3m + 1 (mtotdev), N - 3m (htotdev)."""
    if kind == 'totdev':
        return max(n_phase - 2, 0)
    if kind == 'mtotdev':
        return max(n_phase - 3 * m + 1, 0)
    return max(n_phase - 3 * m, 0)


def bias_factor(kind, alpha, m, n_phase):
    """Factor that divides the raw variance: E[raw] = factor x (AVAR, MVAR or HVAR)."""
    if kind == 'totdev':
        a = TOTVAR_BIAS.get(int(alpha), 0.0)
        return 1.0 - a * m / n_phase
    if kind == 'htotdev' and m > 1:
        return 1.0 + HTOTVAR_BIAS.get(int(alpha), 0.0)
    return 1.0


def edf(kind, alpha, m, n_phase):
    """EDF of the total variances (SP1065 tables 7-9; module docstring)."""
    from ..allan.edf import edf_greenhall
    alpha = int(alpha)
    ratio = n_phase / m
    if kind == 'totdev':
        if alpha in TOTVAR_EDF:
            b, c = TOTVAR_EDF[alpha]
            return b * ratio - c
        return edf_greenhall(alpha, 2, m, n_phase, True, False)
    if kind == 'mtotdev':
        if m < 16:  # short averaging times: the modified variance's (closer to Stable32)
            return edf_greenhall(max(alpha, -2), 2, m, n_phase, True, True)
        b, c = MTOTVAR_EDF[max(min(alpha, 2), -2)]
        return b * ratio - c
    if m < 16 or alpha not in HTOTVAR_EDF:  # the overlapping Hadamard variance's
        return edf_greenhall(alpha, 3, m, n_phase, True, False)
    b0, b1 = HTOTVAR_EDF[alpha]
    return ratio / (b0 + b1 / ratio)
