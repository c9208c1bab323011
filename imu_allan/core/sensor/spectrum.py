"""
The spectral half of :mod:`.sensor`: Welch sums, lines, the white part's autocovariance, humps.

* :class:`Welch`: running sum of Hann-windowed periodograms of L-sample segments (no
  detrending: the periodic Hann window's transform has three nonzero coefficients, so a
  segment's mean reaches bins 0 and 1 only, and its sidelobes fall 18 dB per octave, so
  low-frequency power does not reach the bins searched, 21 and up).
* :func:`find_lines`: bins that stand out from the median of the 32 bins around them (2 left
  out either side), tested with Paulson's normal approximation of the F distribution and a
  Bonferroni bound over the bins tested, false-alarm probability :data:`LINE_FALSE_ALARM` per
  axis; kept when narrow.
* :func:`fit_white`: the white part's R_k as the coefficients of its spectrum, the cosine
  series (2 / fs) [R_0 + 2 sum_k R_k cos(2 pi f k / fs)], fitted to band means of the Welch
  spectrum (lines and humps left out) by weighted least squares; flicker and random-walk
  columns join when significant.  Humps are what stands above it.

Units: the PSD is one-sided, SI^2/Hz; inside the fit it is scaled by fs/2 to per-sample
variance per unit normalised frequency, the units of R_k.
"""

import dataclasses
from dataclasses import dataclass
import functools
import itertools
import math
from statistics import NormalDist

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

#: Line search: background half-width and gap (bins), false-alarm probability per axis.
LINE_HALF_WIDTH, LINE_GAP, LINE_FALSE_ALARM = 16, 2, 0.005
#: The line background's median is taken at every this many bins, interpolated between.
BACKGROUND_STEP = 4
#: First bin searched for lines (the median window must fit above bin 0 and 1).
FIRST_BIN = LINE_HALF_WIDTH + LINE_GAP + 3
#: Bins either side of a line's peak bin left out of the white fit (Hann leakage < 1e-4).
LINE_MASK = 4
#: The cosine series alone is fitted above fs / this; about this many bands of bins.
FIT_LOW_FRACTION, BANDS = 100.0, 256
#: Most lags fitted; significance of a lag (standard errors), and of the first: lower, as a
#: filter missed costs more than one found in error.  A missed lag-1 correlation bends the
#: shortest averaging times the fit takes for white noise (from 10 s at 100 Hz, a rho_1 of
#: 0.1-0.2 left N 5-10 % low and passed for a bias instability); a false one costs the fit
#: only its first averaging time and a fitted deficit.  Lags beyond the first need a
#: correlation at lag 1 anyway.
MAX_LAGS, LAG_SIGNIFICANCE, FIRST_LAG_SIGNIFICANCE = 16, 4.5, 3.0
#: Lags of the fits that find the bands to leave out, tried in turn (few first).
MASK_LAGS_TRIED = (2, 3, 4, 6, 8, 12, 16)
#: Band z above which a band is left out of the fit; largest mean z^2 of the bands kept.
MASK_Z, MASK_CHI2 = 3.0, 2.0
#: Hump: bands above the white part by this many std errors each, and together (sum / sqrt n).
HUMP_EDGE_Z, HUMP_Z, HUMP_MIN_BANDS, HUMP_MIN_BINS = 1.5, 6.0, 3, 12
#: Fraction of the median band below which the white part's spectrum counts as a null.
NULL_FLOOR = 0.01
#: Wald chi^2_2 above which the flicker / random-walk columns are kept (p = 0.003).
LOW_WALD = 11.8

#: Correlation of periodogram values 1 and 2 bins apart for a (periodic) Hann window.
_HANN_BIN_CORR = (4.0 / 9.0, 1.0 / 36.0)
#: Effective degrees of freedom of the running median, per degree of freedom of one bin
#: (measured on white noise: 12.6-13.7 for 8-64 segments; 12 keeps the test conservative).
_MEDIAN_DOF_GAIN = 12.0


@dataclass(frozen=True)
class Line:
    """
    A narrow spectral line (a sinusoid as the ``sinusoid`` noise term describes it).

    ``frequency_hz`` as seen in the sampled data (an alias when the source is above fs/2);
    ``amplitude`` the peak amplitude, SI (rad/s, m/s^2): sqrt(2 P) of the line's mean power P
    over the record (a line whose amplitude wanders gives its root mean square); ``snr`` the
    line's power over the noise power in one Welch bin (Hann: 1.5 fs / L);
    ``false_alarm_probability`` that noise alone gives a peak this high in any of the bins
    tested on this axis (Bonferroni bound).
    """

    frequency_hz: float
    amplitude: float
    snr: float
    false_alarm_probability: float

    def to_json(self):
        """Return a JSON-ready dict (SI)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class Hump:
    """
    A broad resonance: a band where the spectrum stands above the fitted white part.

    ``frequency_range_hz`` (lo, hi); ``peak_hz`` and ``peak_ratio`` (spectrum over the white
    part there, band means); ``excess_variance`` the per-sample variance it adds, SI^2 (lines
    in it left out).
    """

    frequency_range_hz: tuple
    peak_hz: float
    peak_ratio: float
    excess_variance: float

    def to_json(self):
        """Return a JSON-ready dict (SI)."""
        return {**dataclasses.asdict(self), 'frequency_range_hz': list(self.frequency_range_hz)}


@dataclass
class WhitePart:
    """
    The white part's fit: rho_1.. with standard errors, R_0..R_filter_length (per sample).

    ``rho`` holds max(filter_length, 8) lags (fewer for short records), 0 beyond
    filter_length; ``rho_se`` the standard error of each from the fit with that many lags.
    """

    rho: np.ndarray
    rho_se: np.ndarray
    autocovariance: np.ndarray
    humps: list


class Welch:
    """Running sum of Hann-windowed periodograms of L-sample segments."""

    def __init__(self, length):
        """Start an empty sum for segments of ``length`` samples."""
        self.length = length
        self.window = np.sin(np.pi * np.arange(length) / length) ** 2    # periodic Hann
        self.sum = np.zeros(length // 2 + 1)
        self.count = 0

    def add(self, segs):
        """Add segments (K, L); those holding a non-finite value are skipped."""
        # eight at a time: small temporaries are reused from the heap, where 2^18-sample ones
        # would be mapped afresh and page-faulted on every call (3x the time here)
        for i in range(0, segs.shape[0], 8):
            part = segs[i:i + 8]
            power = self._power(part)
            if not np.all(np.isfinite(power)):
                part = part[np.all(np.isfinite(part), axis=1)]
                power = self._power(part)
            self.sum += power
            self.count += part.shape[0]

    def _power(self, part):
        """Sum over segments of |FFT(segment x window)|^2 at bins 0..L/2."""
        with np.errstate(invalid='ignore', over='ignore'):
            spec = np.fft.rfft(part * self.window, axis=1)
        return (np.einsum('ij,ij->j', spec.real, spec.real)
                + np.einsum('ij,ij->j', spec.imag, spec.imag))

    def psd(self, rate_hz):
        """One-sided PSD (SI^2/Hz) at bins 0..L/2 (only 1..L/2-1 are used)."""
        return 2.0 * self.sum / (self.count * rate_hz * (self.window @ self.window))

    def dof(self, spacing):
        """Equivalent degrees of freedom of one bin (Welch 1967), segments ``spacing`` apart."""
        k, w = self.count, self.window
        total = 0.0
        for j in range(1, k):
            shift = j * spacing
            if shift >= self.length:
                break
            total += (k - j) * (w[:-shift] @ w[shift:]) ** 2 / (w @ w) ** 2
        return 2.0 * k / (1.0 + 2.0 * total / k)


def band_factor(n):
    """Variance of the mean of n adjacent Hann periodogram bins, times n, over one bin's."""
    n = np.asarray(n, dtype=float)
    c1, c2 = _HANN_BIN_CORR
    with np.errstate(invalid='ignore', divide='ignore'):
        f = (n + 2.0 * np.maximum(n - 1, 0) * c1 + 2.0 * np.maximum(n - 2, 0) * c2) / n
    return np.where(n > 0, f, 1.0)


def _median_factor(nu):
    """Median of chi^2_nu / nu (Wilson-Hilferty), to turn a median of bins into a mean."""
    return (1.0 - 2.0 / (9.0 * nu)) ** 3


def _paulson_z(ratio, nu1, nu2):
    """Return the normal deviate of an F(nu1, nu2) ratio (Paulson 1942), upper tail."""
    a, b = 2.0 / (9.0 * nu1), 2.0 / (9.0 * nu2)
    c = np.cbrt(ratio)
    return ((1.0 - b) * c - (1.0 - a)) / np.sqrt(b * c * c + a)


def find_lines(psd, nu, length, rate_hz):
    """
    Narrow lines in a Welch PSD; return (lines, background PSD, mask of line bins).

    background[k] is the median of the bins LINE_GAP+1 .. LINE_GAP+LINE_HALF_WIDTH either side
    of k (mirrored at fs/2) over the median of chi^2_nu / nu: the local level without the line
    (NaN outside the bins searched).  A peak is narrow when the excess 3-6 bins from it (other
    peaks left out) is at most 1/4 of its main lobe's (+-2 bins) plus 3 noise standard
    deviations: a Hann-windowed tone leaks under 1e-3 of its power there, a hump much more.
    """
    half = length // 2
    lo, hi = FIRST_BIN, half - 1
    background = np.full(half + 1, np.nan)
    mask = np.zeros(half + 1, dtype=bool)
    reach = LINE_HALF_WIDTH + LINE_GAP
    if hi - lo < 8 or half - 1 <= reach:
        return [], background, mask
    ext = np.concatenate([psd[:half], psd[half - 1:half - 1 - reach:-1]])
    cols = np.r_[0:LINE_HALF_WIDTH, LINE_HALF_WIDTH + 2 * LINE_GAP + 1:2 * reach + 1]
    # the median at every BACKGROUND_STEP-th bin, linear between (a quarter of the cost; the
    # level moves little over 4 bins, and a line near an anchor only raises it: conservative)
    anchors = np.unique(np.r_[np.arange(lo, hi + 1, BACKGROUND_STEP), hi])
    windows = sliding_window_view(ext, 2 * reach + 1)[anchors - reach]
    level = np.median(windows[:, cols], axis=1) / _median_factor(nu)
    background[lo:hi + 1] = np.interp(np.arange(lo, hi + 1), anchors, level)
    bins = np.arange(lo, hi + 1)
    level = background[lo:hi + 1]
    with np.errstate(invalid='ignore', divide='ignore'):
        z = _paulson_z(psd[lo:hi + 1] / level, nu, _MEDIAN_DOF_GAIN * nu)
    tests = bins.size
    z_limit = NormalDist().inv_cdf(1.0 - LINE_FALSE_ALARM / tests)
    cand = np.flatnonzero(z > z_limit)
    peaks = []
    for i in cand[np.argsort(-psd[bins[cand]])]:
        k = int(bins[i])
        if all(abs(k - p) > 2 * LINE_GAP + 1 for p, _ in peaks):
            peaks.append((k, float(z[i])))
    taken = np.zeros(half + 1, dtype=bool)
    for k, _ in peaks:
        taken[k - LINE_GAP:k + LINE_GAP + 1] = True
    df = rate_hz / length
    lines = []
    for k, zk in peaks:
        level = background[k]
        excess = psd - level
        main = excess[k - LINE_GAP:min(k + LINE_GAP + 1, half)].sum()
        outer = [j for j in range(k - 6, k + 7) if abs(j - k) >= 3 and 1 <= j < half
                 and not taken[j]]
        outer_sd = level * math.sqrt(2.0 / nu * len(outer) * float(band_factor(len(outer))))
        if main <= 0 or excess[outer].sum() > 0.25 * main + 3.0 * outer_sd:
            continue
        lines.append(Line(frequency_hz=float(_hann_peak(excess, k, half) * df),
                          amplitude=float(math.sqrt(2.0 * main * df)),
                          snr=float(main / (1.5 * level)),
                          false_alarm_probability=float(min(
                              1.0, tests * 0.5 * math.erfc(zk / math.sqrt(2.0))))))
        mask[max(k - LINE_MASK, 0):k + LINE_MASK + 1] = True
    lines.sort(key=lambda line: line.frequency_hz)
    return lines, background, mask


def _hann_peak(excess, k, half):
    """Fractional bin of a tone from the Hann amplitude ratio of its two largest bins."""
    left = excess[k - 1]
    right = excess[k + 1] if k + 1 < half else 0.0
    r = math.sqrt(max(left, right, 0.0) / excess[k])
    # |X(k+1)| / |X(k)| = (1 + d) / (2 - d) for a tone at k + d under a periodic Hann window
    d = min(max((2.0 * r - 1.0) / (1.0 + r), 0.0), 0.5)
    return k + (d if right >= left else -d)


class _Bands:
    """
    The spectrum from FIRST_BIN up, averaged over bands of adjacent bins, lines left out.

    Least squares on band means is as good as on bins for models smooth within a band (the
    regressors are averaged exactly) and ``band`` times cheaper; humps are left out of the fit
    a band at a time.  ``y`` is the PSD times fs / 2, ``x`` the regressors (:func:`_columns`),
    ``rel_var`` the relative variance of each band mean.
    """

    def __init__(self, psd, background, line_mask, nu, length, rate_hz, lags):
        half = length // 2
        count = half - FIRST_BIN
        self.length = length
        self.band = _band_size(length)
        nb = -(-count // self.band)
        bins = np.arange(FIRST_BIN, FIRST_BIN + nb * self.band)
        inside = bins < half
        at = np.minimum(bins, half - 1)
        keep = (inside & ~line_mask[at]).reshape(nb, self.band)
        self.count = keep.sum(axis=1)
        self.width = inside.reshape(nb, self.band).sum(axis=1)    # bins per band, lines too
        self.low_bin = max(int(math.ceil(length / FIT_LOW_FRACTION)), FIRST_BIN)
        per_bin = np.column_stack([psd[at], background[at]]) * (rate_hz / 2.0)
        per_bin = np.hstack([per_bin, _columns(int(bins[0]), int(bins[-1]) + 1, lags, length,
                                               self.low_bin)])
        with np.errstate(invalid='ignore', divide='ignore'):
            means = np.einsum('bj,bjc->bc', keep, np.nan_to_num(per_bin).reshape(
                nb, self.band, -1)) / self.count[:, None]
        self.y, guide, self.x = means[:, 0], means[:, 1], means[:, 2:]
        self.valid = self.count > 0
        fallback = np.median(self.y[self.valid]) if self.valid.any() else 1.0
        self.guide = np.where(self.valid & (guide > 0), guide, fallback)
        # below this a band's model is a spectral null: its relative error means nothing
        self.floor = NULL_FLOOR * fallback
        self.rel_var = 2.0 / nu * band_factor(self.count) / np.maximum(self.count, 1)
        self.centre = bins.reshape(nb, self.band).mean(axis=1)
        self.high = self.valid & (self.centre >= self.low_bin)
        self.first = bins[::self.band]
        self.lags = lags

    def z(self, model):
        """(band mean - model) / its standard error, 0 outside the high bands."""
        with np.errstate(invalid='ignore', divide='ignore'):
            z = (self.y - model) / (np.maximum(model, self.floor) * np.sqrt(self.rel_var))
        return np.where(self.high & np.isfinite(z), z, 0.0)


def _band_size(length):
    """Bins per band: about :data:`BANDS` bands from FIRST_BIN to fs/2."""
    return max(1, int(round((length // 2 - FIRST_BIN) / BANDS)))


@functools.lru_cache(maxsize=8)
def _columns(first, stop, lags, length, low_bin):
    """
    Regressors at bins first..stop-1: 1, 2 cos(2 pi k i / L) (i = 1..lags), flicker, walk.

    The cosines' coefficients are R_0, R_i; then (s0 / s) and (s0 / s)^2 with s = sin(pi k /
    L), s0 its value at ``low_bin``: the sampled flicker and random-walk spectra, 1 there.
    (Cached: every axis of a record has the same; read-only.)
    """
    bins = np.arange(first, stop)
    x = np.pi / length * bins
    cos = 2.0 * np.cos(2.0 * np.outer(x, np.arange(1, lags + 1)))
    low = math.sin(math.pi * low_bin / length) / np.sin(x)
    out = np.column_stack([np.ones(bins.size), cos, low, low * low])
    out.flags.writeable = False
    return out


def _wls(y, x, rel_var, guide, floor):
    """
    Weighted least squares of band means on regressors, weights from a model; two passes.

    Returns (coefficients, covariance from the band errors alone, chi^2 / dof).  Solved by the
    normal equations (a few hundred bands, at most 19 well-scaled columns).
    """
    for _ in range(2):
        sd = np.maximum(guide, floor) * np.sqrt(rel_var)
        a = x / sd[:, None]
        try:
            inv = np.linalg.inv(a.T @ a)
        except np.linalg.LinAlgError:
            inv = np.linalg.pinv(a.T @ a)
        coef = inv @ (a.T @ (y / sd))
        guide = x @ coef
    resid = (y - guide) / sd
    return coef, inv, float(resid @ resid) / max(y.size - x.shape[1], 1)


class _Fit:
    """
    The cosine series with ``lags`` lags fitted to the bands outside ``mask``.

    With ``use_low`` None the flicker and random-walk columns are tried with it from the
    lowest band up and kept when significant (Wald chi^2_2 > :data:`LOW_WALD`): their shapes
    are told from the cosines only by the steep low band, which costs precision, so only when
    needed; otherwise the cosines alone are fitted above fs/100.  ``coef`` None: too few bands.
    """

    def __init__(self, bands, mask, lags, use_low=None):
        self.lags, self.coef, self.cov, self.stat_cov = lags, None, None, None
        self.use_low = use_low
        cos_idx, low_idx = list(range(lags + 1)), [bands.lags + 1, bands.lags + 2]
        rows = bands.valid & ~mask
        if np.count_nonzero(rows & bands.high) < lags + 6:
            return
        if use_low is None:
            coef, cov, _ = _wls(bands.y[rows], bands.x[rows][:, cos_idx + low_idx],
                                bands.rel_var[rows], bands.guide[rows], bands.floor)
            low, low_cov = coef[-2:], cov[-2:, -2:]
            self.use_low = bool(np.all(np.isfinite(cov)) and np.linalg.cond(cov) < 1e10
                                and low @ np.linalg.solve(low_cov, low) > LOW_WALD)
        self.idx = cos_idx + (low_idx if self.use_low else [])
        rows = rows if self.use_low else rows & bands.high
        self.coef, self.stat_cov, chi2 = _wls(bands.y[rows], bands.x[rows][:, self.idx],
                                              bands.rel_var[rows], bands.guide[rows],
                                              bands.floor)
        # a misfit (chi^2 / dof > 1) widens the errors reported
        self.cov = self.stat_cov * max(1.0, chi2)

    def rho_se(self, k):
        """Return the standard error of rho_k = R_k / R_0 (delta method: R_0, R_k covary)."""
        r0, rk, c = self.coef[0], self.coef[k], self.cov
        if not r0 > 0:
            return math.nan
        var = c[k, k] - 2.0 * rk / r0 * c[0, k] + (rk / r0) ** 2 * c[0, 0]
        return math.sqrt(max(var, 0.0)) / r0

    def model(self, bands, low_only=False):
        """Return the fitted spectrum at each band (only its flicker / random-walk part)."""
        if low_only:
            if not self.use_low:
                return 0.0
            return bands.x[:, self.idx[-2:]] @ self.coef[-2:]
        return bands.x[:, self.idx] @ self.coef


def fit_white(psd, nu, length, rate_hz, line_mask, background):
    """
    Fit the white part of a Welch PSD and find the humps above it; WhitePart or None.

    The bands to leave out come from the first k in :data:`MASK_LAGS_TRIED` whose fit matches
    the bands kept (:func:`_settle_mask`: few lags first, as a fit with many more lags than the
    filter follows a hump); then lags join while significant (:func:`_forward`), and
    R_0..R_filter_length and the humps come from the fit with filter_length lags.  A mask that
    reaches down to the lowest band fitted, or whose final fit is no white part (R_0 or
    S = R_0 + 2 sum R_k not positive), is the filter's main lobe taken for a hump by too stiff
    a fit: more lags are tried.  docs/method.md section 9 ("The white part") says why.
    """
    half = length // 2
    low_bin = max(int(math.ceil(length / FIT_LOW_FRACTION)), FIRST_BIN)
    high_bands = (half - low_bin) // _band_size(length)
    if high_bands < 8:
        return None
    lags = int(min(MAX_LAGS, max(high_bands // 4 - 3, 0)))
    bands = _Bands(psd, background, line_mask, nu, length, rate_hz, lags)
    masks = (_settle_mask(bands, k) for k in sorted({min(k, lags) for k in MASK_LAGS_TRIED}))
    # the last: no number of lags explains the rest, so leave out nothing
    lowest = int(np.argmax(bands.high))
    for mask in itertools.chain(masks, [np.zeros(bands.y.size, dtype=bool)]):
        if mask is None or mask[lowest]:
            continue
        filter_length, use_low, rho_se = _forward(bands, mask, lags)
        final = _Fit(bands, mask, filter_length, use_low)
        if (final.coef is not None and final.coef[0] > 0
                and final.coef[0] + 2.0 * final.coef[1:filter_length + 1].sum() > 0):
            break
    else:
        return None
    rho = np.zeros(rho_se.size)
    rho[:filter_length] = final.coef[1:filter_length + 1] / final.coef[0]
    rho_se[:filter_length] = [final.rho_se(k) for k in range(1, filter_length + 1)]
    model = final.model(bands)
    low = final.model(bands, low_only=True)
    humps = _measure_humps(_hump_runs(bands.z(model), bands.band), bands.y - low, model - low,
                           bands, rate_hz)
    return WhitePart(rho, rho_se, final.coef[:filter_length + 1], humps)


def _settle_mask(bands, lags):
    """
    Find the bands to leave out of a fit with ``lags`` lags (:func:`fit_white`), or None.

    None when the lags are too few for the filter rather than a hump being in the way: the
    bands kept then still miss the fit (chi^2 / dof > :data:`MASK_CHI2`, or more than 2 % of
    them more than MASK_Z standard errors below it: a fit pulled up by a hump it cannot follow
    is too high elsewhere, and once the hump is left out relaxes; a fit too stiff for the
    filter stays off everywhere), or fewer than half the bands are kept.
    """
    mask = np.zeros(bands.y.size, dtype=bool)
    use_low = None
    for it in range(12):
        fit = _Fit(bands, mask, lags, use_low)
        if fit.coef is None:
            return None
        use_low = fit.use_low     # tried once: the mask hardly changes it
        z = bands.z(fit.model(bands))
        grown = z > MASK_Z
        if it >= 3:     # from here on only grow: a band at a spectral null can flip back
            grown |= mask
        if np.array_equal(grown, mask):
            break
        mask = grown
    kept = bands.high & ~mask
    if (np.count_nonzero(kept) < np.count_nonzero(bands.high) // 2
            or np.mean(z[kept] ** 2) > MASK_CHI2 or np.mean(z[kept] < -MASK_Z) > 0.02):
        return None
    mask = _dilate(mask, 1)
    for s, e in _hump_runs(z, bands.band):
        mask[max(s - (e - s) // 2, 0):e + (e - s) // 2] = True
    return mask


def _significant(fit, j):
    """Return whether lag ``j``'s coefficient in ``fit`` is clear of 0 (its level's sigmas)."""
    se = math.sqrt(max(fit.stat_cov[j, j], 0.0))
    level = FIRST_LAG_SIGNIFICANCE if j == 1 else LAG_SIGNIFICANCE
    return se > 0 and abs(fit.coef[j]) > level * se


def _forward(bands, mask, lags):
    """
    Lags kept by forward selection; (filter_length, use_low, standard errors of rho_k).

    The fit with k lags is kept when any lag in it beyond those kept so far (not only lag k:
    a window spanning two lags makes the one-lag fit degenerate, docs/method.md section 9) is
    more than :data:`LAG_SIGNIFICANCE` standard errors from 0 (:data:`FIRST_LAG_SIGNIFICANCE`
    for the first), from the band errors alone (scaling them by a fit with too few lags would
    hide the lag that mends it); two misses in a row stop.  The standard error of rho_k is the
    k-lag fit's (misfit included), for k up to max(filter_length, 8).
    """
    filter_length, use_low, misses, rho_se = 0, None, 0, []
    for k in range(1, lags + 1):
        fit = _Fit(bands, mask, k)
        if fit.coef is None:
            break
        rho_se.append(fit.rho_se(k))
        if misses < 2:
            if any(_significant(fit, j) for j in range(filter_length + 1, k + 1)):
                filter_length, use_low, misses = k, fit.use_low, 0
            else:
                misses += 1
        if misses == 2 and k >= 8:
            break
    if use_low is None:
        use_low = bool(_Fit(bands, mask, 0).use_low)
    return filter_length, use_low, np.array(rho_se)


def _measure_humps(runs, ybar, mbar, bands, rate_hz):
    """Return a :class:`Hump` for each run of bands, against the white part ``mbar``."""
    df = rate_hz / bands.length
    humps = []
    for s, e in runs:
        excess = ybar[s:e] - mbar[s:e]
        j = s + int(np.argmax(excess))
        humps.append(Hump(
            frequency_range_hz=(float(bands.first[s] * df),
                                float((bands.first[s] + bands.width[s:e].sum() - 1) * df)),
            peak_hz=float(bands.centre[j] * df),
            peak_ratio=float(ybar[j] / mbar[j]),
            # per unit normalised frequency -> per sample: bins times 2 / L
            excess_variance=float((excess * bands.width[s:e]).sum() * 2.0 / bands.length)))
    return humps


def _hump_runs(z, band):
    """(start, stop) band indices of the runs of z that make a hump."""
    if z.size < HUMP_MIN_BANDS + 2:
        return []
    return [(s, e) for s, e in _runs(z > HUMP_EDGE_Z)
            if e - s >= HUMP_MIN_BANDS and (e - s) * band >= HUMP_MIN_BINS
            and z[s:e].sum() / math.sqrt(e - s) > HUMP_Z]


def _runs(flags):
    """(start, stop) of each run of True in a boolean array."""
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))


def _dilate(flags, width):
    """Boolean array with every True widened by ``width`` elements either side."""
    if not flags.any():
        return flags.copy()
    return np.convolve(flags.astype(float), np.ones(2 * width + 1), mode='same') > 0
