"""
The averaging times a fit may use, and the shape the sensor's own processing gives white noise.

Real IMUs filter their samples, resonate and carry vibration lines (docs/method.md, "Sensor
processing").  None of that is an IEEE 952 term, and each bends the short end of the Allan curve,
where the estimates have the most degrees of freedom and so the most weight: a fit that ignores
it puts N 15-32 % low and B 2-40x high on real ADIS16405 records, while the conventional reading
(IEEE 952, allan_variance_ros, MATLAB's allanvar) takes N from the -1/2 region.  What each
effect does at tau = m tau0:

* a filter (band-limited white noise; sample-and-hold repeats are one): for m at or beyond its
  correlation length L the white part's AVAR is exactly N^2 / tau - 1.5 (D / S) N^2 / (fs tau^2)
  (D / S the filter moment).  The fit starts at m = L + 1 (one sample beyond the closed form's
  reach, for a correlation the measurement cut short).  A measured moment only says there is
  a deficit: the fit adds its column -tau0 / tau^2, its size fitted (:class:`~.axis.Problem`).
  A known one (the device's moving average, ``filter_known``) gives the deficit exactly: white
  noise's own shape is then N^2 (1 / tau - 1.5 (D / S) tau0 / tau^2), nothing more fitted (a
  free deficit trades against N, doubles N's spread and lets N take an unresolved flicker
  floor from the longer averaging times: issue 35).  A negative moment is white phase noise's
  own (quantization Q, a term of the fit): no correction then.
* a narrow line of amplitude A at f (aliased or not): A^2 sin^4(pi f tau) / (pi f tau)^2.  Every
  line visible in the curve is fitted at the frequency the spectrum shows, the most visible one
  as the ``sinusoid`` term (one per axis: the noise model holds one sinusoid), the others as
  nuisance columns of the fit (``AxisFit.lines``): a line is the sensor's, not a reason to
  lose the averaging times it crosses.
* a broad resonance of excess variance P over [f_lo, f_hi]: P times
  :func:`~imu_allan.core.terms.band_shape`, on average 3 P / (4 (pi f tau)^2) beyond 1 / f_lo.

What is not fitted (a resonance) is cut away: the fit starts at the shortest averaging time from
which each of them stays below :data:`KAPPA` standard deviations of the AVAR estimate
(sqrt(2 / EDF)) at that time and every longer one.  Why a fraction of the estimate's own scatter:
a systematic shift of a third of a standard deviation over strongly correlated points moves a
coefficient by a small part of its interval; shifts of many deviations are what bias the
ADIS16405 fits.
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
