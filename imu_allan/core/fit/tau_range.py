"""
The averaging times a fit may use, and the shape the sensor's own processing gives white noise.

Real IMUs filter their samples, resonate and carry vibration lines; each bends the short end of
the Allan curve, where the estimates weigh most (N 15-32 % low, B 2-40x high on real ADIS16405
records when ignored).  Per effect at tau = m tau0 (docs/method.md section 10):

* a filter (moment D / S, correlation length L): from m = L + 1 on the white part's AVAR is
  N^2 / tau - 1.5 (D / S) N^2 / (fs tau^2); a measured moment's deficit is a fitted nuisance
  column -tau0 / tau^2 (:class:`~.axis.Problem`), a known one's (``filter_known``) is tied to
  N in white noise's own shape.  A negative moment is quantization's own: no correction;
* a narrow line of amplitude A at f: A^2 sin^4(pi f tau) / (pi f tau)^2, fitted at the
  spectrum's frequency, the most visible as the ``sinusoid`` term, the others as nuisance;
* a broad resonance of excess variance P over [f_lo, f_hi]: P times
  :func:`~imu_allan.core.terms.band_shape`, not fitted: the span starts where it stays below
  :data:`KAPPA` standard deviations of the AVAR estimate (sqrt(2 / EDF)) at every longer tau.
"""

from dataclasses import dataclass
import math

import numpy as np

from ..terms import band_shape, sinusoid_shape

#: Largest effect of the processing not fitted allowed at a fitted averaging time, in standard
#: deviations of its AVAR estimate.
KAPPA = 0.3
#: Fewest averaging times a fit keeps, however far the processing reaches.
MIN_POINTS = 8


@dataclass(frozen=True)
class Processing:
    """
    What a sensor's own processing does to one axis (measured, :mod:`..sensor`, or known).

    ``filter_length``: output samples over which the white noise is correlated (0: none);
    ``filter_moment``: D / S of that correlation (samples; positive for a low-pass);
    ``filter_known``: the moment is the device's own, exact (a known moving average), not a
    measurement: the fit ties the deficit to N (:class:`~.axis.Problem`);
    ``lines``: ``((frequency_hz, amplitude), ...)`` narrow lines (peak amplitude, SI);
    ``humps``: ``((f_lo_hz, f_hi_hz, excess_variance), ...)`` broad resonances (SI^2).
    """

    filter_length: int = 0
    filter_moment: float = 0.0
    lines: tuple = ()
    humps: tuple = ()
    filter_known: bool = False

    @classmethod
    def moving_average(cls, window_samples):
        """
        Return the filter of a moving average ``window_samples`` output samples long.

        A window of M taps at an internal rate, decimated by D to the output, gives white
        noise the autocorrelation max(0, 1 - k / w) at output lag k, w = M / D (the
        3DM-GX3-25's 0xDB window: 15 taps at 1 kHz, w = 1.5 at 100 Hz).
        """
        w = float(window_samples)
        k = np.arange(1, max(math.ceil(w), 1))
        rho = np.maximum(0.0, 1.0 - k / w) if w > 1.0 else np.zeros(0)
        s = 1.0 + 2.0 * rho.sum()
        return cls(int(k.size), float(2.0 * np.sum(k * rho) / s), filter_known=True)


@dataclass
class TauRange:
    """The averaging times a fit uses, why its lower end is where it is, and its shapes."""

    lo: float
    hi: float
    #: what set the lower end: 'filter', 'line', 'resonance', 'asked' or None (the shortest)
    limited_by: str = None
    #: the line fitted as the sinusoid term: (frequency_hz, amplitude) or None
    line: tuple = None
    #: the other visible lines, fitted as nuisance (the sensor's): ((frequency_hz, amplitude),)
    lines: tuple = ()

    #: D / S given to white noise's shape (0: none), samples
    filter_moment: float = 0.0
    #: the moment is known exactly (the device's window): the deficit is tied to N, not fitted
    filter_known: bool = False

    @property
    def deficit_per_white(self):
        """Return a known filter's AVAR deficit per N^2 and tau0 / tau^2: 1.5 D / S (0: none)."""
        return 1.5 * self.filter_moment if self.filter_known and self.filter_moment > 0 else 0.0

    def known_deficit(self, tau, rate_hz):
        """
        Return a known filter's AVAR deficit per unit N^2 at ``tau`` (s): 1.5 (D/S) tau0/tau^2.

        White noise's shape in a fit on this span is 1 / tau less this (0 without a known
        filter); a model curve compared with such a fit carries it too.
        """
        tau = np.asarray(tau, dtype=float)
        return self.deficit_per_white / (rate_hz * tau * tau)

    def to_json(self):
        """JSON-ready ``[lo, hi]`` (report.json ``axes.<axis>.fit.tau_range_s``)."""
        return [float(self.lo), float(self.hi)]


def choose(processing, tau, avar, edf, rate_hz):
    """
    Return the fit's span of averaging times for one axis (a :class:`TauRange`).

    ``tau``, ``avar``, ``edf``: the measured curve (usable points, increasing tau);
    ``processing``: a :class:`Processing` or None (then the whole curve, plain shapes).
    """
    tau = np.asarray(tau, dtype=float)
    avar = np.asarray(avar, dtype=float)
    if tau.size == 0:
        return TauRange(math.nan, math.nan)
    if processing is None:
        return TauRange(float(tau[0]), float(tau[-1]))
    sd = np.sqrt(2.0 / np.asarray(edf, dtype=float))
    visible = _visible_lines(processing, tau, avar, sd, KAPPA)
    line, others = (visible[0], tuple(visible[1:])) if visible else (None, ())
    moment = max(processing.filter_moment, 0.0)
    start, limited_by = 0, None
    if moment > 0.0:
        start = int(np.searchsorted(tau * rate_hz, processing.filter_length + 1 - 1e-9))
        limited_by = 'filter' if start else None
    if processing.humps:  # cut where a resonance shifts the estimate by more than KAPPA sd
        size = sum(p * band_shape(tau, lo, hi) for lo, hi, p in processing.humps) / avar
        over = np.flatnonzero(size > KAPPA * sd)
        if over.size and over[-1] + 1 > start:
            start, limited_by = int(over[-1]) + 1, 'resonance'
    start = min(start, max(tau.size - MIN_POINTS, 0))
    return TauRange(float(tau[start]), float(tau[-1]), limited_by if start else None, line,
                    others, moment, bool(processing.filter_known and moment > 0.0))


def _visible_lines(processing, tau, avar, sd, kappa):
    """Return the lines visible in the curve (AVAR / estimate sd above kappa), most first."""
    seen = []
    for f, a in processing.lines:
        visibility = float(np.max(a * a * sinusoid_shape(tau, f) / avar / sd))
        if visibility > kappa:
            seen.append((visibility, (f, a)))
    return [line for _, line in sorted(seen, reverse=True)]
