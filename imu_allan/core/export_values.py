"""
The numbers every exporter starts from: a fitted term per axis, inflated, or its upper limit.

One place for the rules the Kalibr file introduced and every exporter shares (the exporters in
:mod:`imu_allan.report.exporters` only name and convert what :class:`ExportValues` gives):

* values are the fitted continuous-time coefficients (SI, :mod:`imu_allan.core.units`);
* a term the fit did not select is replaced by its 95 % upper limit
  (:meth:`imu_allan.core.fit.FittedModel.upper_limit`) and remembered, so the file can mark it;
  so is a value from an axis whose model the adequacy test rejects
  (:mod:`imu_allan.core.fit.adequacy`);
* ``inflate = (white, walk)`` multiplies the standard deviations: ``white`` the white noise N,
  ``walk`` the bias terms (random walk K, bias instability B);
* a single-valued key takes the worst (largest) axis of its sensor; which axis, and whether it
  was an upper limit, is recorded per key for the file header;
* with ``overbound`` (the :class:`~imu_allan.core.record.OverboundValues` computed with the
  record) the terms of the consumer's own model (:attr:`ExportValues.model`) take the values of
  :func:`imu_allan.core.overbound.overbound` instead, the inflation on top; per key the factor
  against the raw value and the tight averaging times are recorded (:func:`overbound_block`);
* an analysis whose motion verdict says the IMU moved gives no values (its curve measures the
  motion, not the sensor noise) unless it was run with ``allow_motion``
  (``analyze --allow-motion``).
"""

import math

from .analysis import Analysis
from .overbound import OVERBOUND_LEVEL, WHITE_WALK
from .units import AXES, sensor_of

#: Which inflation factor (index into ``inflate``) scales each term; others are not inflated.
INFLATED_BY = {'white_noise': 0, 'rate_random_walk': 1, 'bias_instability': 1}
#: Upper bound of an inflation factor (users report 10-100x; above 1000 is a typo).
MAX_INFLATE = 1000.0


def check_inflate(inflate):
    """Return ``(white, walk)`` from a number or a pair; ValueError unless 0 < f <= 1000."""
    if isinstance(inflate, (int, float)):
        inflate = (inflate, inflate)
    white, walk = (float(f) for f in inflate)
    for factor in (white, walk):
        if not (math.isfinite(factor) and 0.0 < factor <= MAX_INFLATE):
            raise ValueError(f'inflation factor {factor:g} must be > 0 and <= {MAX_INFLATE:g}')
    return white, walk


def fit_of(fitted):
    """Return the FittedModel of ``fitted`` (a FittedModel, or an Analysis: its ``fit``)."""
    return fitted.fit if isinstance(fitted, Analysis) else fitted


def motion_withheld(analysis):
    """Return whether ``analysis`` (an Analysis or None) moved without ``allow_motion``."""
    return analysis is not None and not analysis.static and not analysis.allow_motion


class ExportValues:
    """
    Per-axis values of a fitted model, ready for an exporter (SI, continuous time).

    ``fitted`` is a :class:`~imu_allan.core.fit.FittedModel` or an
    :class:`~imu_allan.core.analysis.Analysis` (its ``fit``, motion verdict and source).
    """

    def __init__(self, fitted, rate_hz=None, inflate=1.0, source=None, topic='/imu/data_raw',
                 overbound=None, model=WHITE_WALK):
        """
        Collect from ``fitted``; ``rate_hz`` (Hz) defaults to the rate the model was fitted at.

        ``overbound``: None (raw values) or the :class:`~imu_allan.core.record.OverboundValues`
        holding the fits of ``model`` (the consumer's terms, what is overbounded).
        """
        #: the Analysis when one was given (its motion verdict and source), else None
        self.analysis = fitted if isinstance(fitted, Analysis) else None
        self.fit = fit_of(fitted)
        self.fitted_rate_hz = float(self.fit.rate_hz)
        self.rate_hz = float(rate_hz) if rate_hz else self.fitted_rate_hz
        if not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f'rate {rate_hz!r} Hz must be a positive number')
        self.inflate = check_inflate(inflate)
        self.source = source or (self.analysis.source if self.analysis else None) or 'fitted model'
        self.topic = topic
        #: key -> {'axes': [axis, ...], 'upper': [axis, ...], 'inadequate': [...]} for the header
        self.used = {}
        self.overbound = overbound
        self.model = tuple(model)
        #: key -> {'factor': {axis: x}, 'tight_tau_s': {axis: [s, ...]}} (overbound only)
        self.overbound_used = {}
        self._last_overbound = {}
        #: the record moved and motion was not allowed: nothing is exported
        self.motion_withheld = motion_withheld(self.analysis)

    @property
    def horizon_s(self):
        """Return the overbound horizon (s): as asked, else the longest measured tau; None: raw."""
        if self.overbound is None:
            return None
        horizon = self.overbound.horizon_s
        return float(self.fit.result.tau[-1]) if horizon is None else float(horizon)

    def overbound_fit(self, axes, shapes=None):
        """
        :class:`~imu_allan.core.overbound.OverboundFit` of ``shapes`` (default: the model).

        ``axes``: one axis, or several whose envelope one model must bound.  Raises the
        :class:`~imu_allan.core.overbound.OverboundError` it could not be made for.
        """
        fit = self.overbound.get(axes, shapes or self.model)
        if fit is None:
            raise KeyError(f'no overbound of {shapes or self.model} over {axes} was computed')
        return fit

    def note_overbound(self, key, axis, factor, tight_tau):
        """Record, for ``key`` on ``axis``, the factor against the raw value and the tight taus."""
        entry = self.overbound_used.setdefault(key, {'factor': {}, 'tight_tau_s': {}})
        entry['factor'][axis] = float(factor)
        entry['tight_tau_s'][axis] = [float(t) for t in tight_tau]

    def axes(self, sensor):
        """Fitted axes of ``'gyro'`` or ``'accel'``, in the package's order."""
        return [a for a in AXES if a in self.fit.axes and sensor_of(a) == sensor]

    def value(self, axis, term, param='value'):
        """``(value, is_upper_limit)`` of one term on one axis, inflated; NaN if unknown."""
        factor = self.inflate[INFLATED_BY[term]] if term in INFLATED_BY else 1.0
        if self.motion_withheld:
            return math.nan, False
        raw, upper = self.raw_value(axis, term, param)
        if (self.overbound is None or term not in self.model or param != 'value'
                or axis not in self.fit.axes):
            return raw * factor, upper
        fit = self.overbound_fit(axis)
        value = fit.value(term)
        if not value > 0:   # the bound does not need the term; consumers refuse zeros
            return raw * factor, upper
        self._last_overbound[(axis, term)] = (value / raw if raw > 0 else math.nan,
                                              fit.tight_tau)
        return value * factor, False

    def raw_value(self, axis, term, param='value'):
        """``(value, is_upper_limit)`` of the fit (or its upper limit), not inflated."""
        value = self.fit.value(axis, term, param) if axis in self.fit.axes else math.nan
        if math.isfinite(value):
            return value, False
        if axis not in self.fit.axes or param != 'value':
            return math.nan, False
        limit = self.fit.upper_limit(axis, term)
        return limit, math.isfinite(limit)

    def _record(self, key, axes, upper, term=None):
        self.used[key] = {'axes': list(axes), 'upper': [a for a, u in zip(axes, upper) if u],
                          'inadequate': [a for a in axes if self.inadequate(a)]}
        for axis in axes:
            if (axis, term) in self._last_overbound:
                self.note_overbound(key, axis, *self._last_overbound[(axis, term)])

    def worst(self, sensor, term, key):
        """Return the largest value over the sensor's axes (None if none is known), for ``key``."""
        best = None
        for axis in self.axes(sensor):
            value, upper = self.value(axis, term)
            if math.isfinite(value) and (best is None or value > best[0]):
                best = (value, axis, upper)
        if best is None:
            self._record(key, [], [])
            return None
        self._record(key, [best[1]], [best[2]], term)
        return best[0]

    def per_axis(self, sensor, term, key):
        """Values for the x, y, z axes of ``sensor`` (None where an axis is missing)."""
        axes = [f'{sensor}_{c}' for c in 'xyz']
        pairs = [self.value(a, term) for a in axes]
        out = [v if math.isfinite(v) else None for v, _ in pairs]
        self._record(key, [a for a, (v, _) in zip(axes, pairs) if math.isfinite(v)],
                     [u for v, u in pairs if math.isfinite(v)], term)
        return out

    def upper_limit_keys(self):
        """Keys (with axes) written as 95 % upper limits because the term was not detected."""
        return {k: u['upper'] for k, u in self.used.items() if u['upper']}

    def inadequate(self, axis):
        """Return whether the adequacy test rejects the model of ``axis`` (not: untested)."""
        adequacy = self.fit.adequacy(axis)
        return adequacy is not None and adequacy.rejected

    def inadequate_keys(self):
        """Keys (with axes) taken from an axis whose model the adequacy test rejects."""
        return {k: u['inadequate'] for k, u in self.used.items() if u['inadequate']}

    def overbound_summary(self):
        """Return this consumer's ``exports.<name>`` entry of the ``overbound`` block."""
        return {key: {'factor': {a: (f if math.isfinite(f) else None)
                                 for a, f in entry['factor'].items()},
                      'tight_tau_s': entry['tight_tau_s']}
                for key, entry in self.overbound_used.items()}


def overbound_block(fitted, overbound, consumers, inflate=1.0):
    """
    Return the ``overbound`` block of report.json: horizon (s), level, inflation, per consumer.

    ``fitted``: FittedModel or Analysis; ``overbound``: its OverboundValues; ``consumers``:
    ``(name, model, build)`` triples, ``build(values)`` the exporter's (what it asks of an
    :class:`ExportValues` decides the keys).  ``exports.<name>.<key>`` holds per axis the
    factor against the raw fit (its upper limit where not detected) and the tight taus.
    """
    exports, horizon = {}, None
    for name, model, build in consumers:
        values = ExportValues(fitted, inflate=inflate, overbound=overbound, model=model)
        build(values)
        exports[name], horizon = values.overbound_summary(), values.horizon_s
    return {'horizon_s': horizon, 'level': OVERBOUND_LEVEL,
            'inflate': list(check_inflate(inflate)), 'exports': exports}
