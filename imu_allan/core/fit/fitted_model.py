"""
A noise model fitted to every axis of an Allan deviation: :func:`fit_noise_model`.

Per axis (:mod:`.axis` holds the machinery): the averaging times the sensor's own processing
does not shape (:mod:`.tau_range`; all of them without a processing description), a line the
spectrum shows fitted as the ``sinusoid`` term at its frequency, the IEEE 952 terms selected
(chi^2 + 2 k ln T), the Hadamard check of a rate random walk against a ramp when the OHDEV
curve is given (:mod:`.hadamard_check`), and last the adequacy test of the result
(:mod:`.adequacy`): where the model does not describe the curve the intervals are widened by the
Birge ratio and the spans it misses are named.
"""

import math

import numpy as np

from . import hadamard_check
from .adequacy import assess, STATISTIC_SCALE
from .averaging import averaged_interval, selection_gain, weights
from .axis import (
    fit_axis,
    fit_terms,
    problem_upper_limit,
    ramp_cross_sd,
    two_sided_z,
    usable_points,
    widen,
)
from .tau_range import choose, TauRange
from .. import terms as _terms
from ..allan.edf import CI_LEVEL
from ..model import NoiseModel
from ..terms import sinusoid_shape, TERMS
from ..units import conventional, IEEE_TERMS, si_unit

#: Open term sets an upper limit is computed in, the best first (each costs a profile).
LIMIT_SETS = 4
#: Confidence of the upper limits (profile delta chi^2 = 4, :data:`.axis.UPPER_LIMIT_DELTA_CHI2`).
LIMIT_LEVEL = 0.95


class FittedModel:
    """Result of :func:`fit_noise_model`: a :class:`NoiseModel` plus intervals per term."""

    def __init__(self, fits, rate_hz, result=None):
        """
        Wrap per-axis :class:`AxisFit` objects.

        :attr:`model` holds the resolved terms only (:meth:`resolved`): what the data show,
        with the values of the selected set's fit; the others are upper limits.
        """
        self.fits = fits
        self.rate_hz = rate_hz
        self.result = result
        self.model = NoiseModel({a: {t: p for t, p in f.terms.items() if t in self.resolved(a)}
                                 for a, f in fits.items()}, rate_hz)
        self._weights = {}
        for axis, fit in fits.items():  # the stored 68.3 % intervals carry the choice of terms
            for term in self.model.terms[axis]:
                if term in fit.coef and fit.candidates:
                    fit.intervals[term] = TERMS[term].pack(
                        self.averaged_interval(axis, term, CI_LEVEL),
                        TERMS[term].unpack(fit.intervals[term])[1])
        self.intervals = {a: f.intervals for a, f in fits.items()}
        self.chi2 = {a: f.chi2 for a, f in fits.items()}
        self.dof = {a: f.dof for a, f in fits.items()}

    @property
    def axes(self):
        """Fitted axes."""
        return list(self.fits)

    def value(self, axis, term, param='value'):
        """Return a fitted parameter (SI, continuous time), NaN if the term was not detected."""
        return self.model.value(axis, term, param)

    def interval(self, axis, term, param='value', level=CI_LEVEL):
        """
        Return the two-sided ``level`` interval of a parameter, ``(nan, nan)`` if not detected.

        ``level`` defaults to 68.27 %, the interval stored with the fit.  Main parameters:
        :meth:`averaged_interval`; tau_c / f0: the stored interval's log half-widths scaled by
        z = Phi^-1((1 + level) / 2).
        """
        stored = self.intervals.get(axis, {}).get(term, {}).get(param)
        if stored is None:
            return (math.nan, math.nan)
        if not 0.0 < level < 1.0:
            raise ValueError(f'confidence level {level!r} must be between 0 and 1')
        if abs(level - CI_LEVEL) < 1e-12:
            return stored
        fit = self.fits[axis]
        value = self.model.value(axis, term, param)
        if param == TERMS[term].params[0] and term in fit.coef:
            return self.averaged_interval(axis, term, level)
        z = two_sided_z(level)
        lo, hi = stored
        return (value * (lo / value) ** z, value * (hi / value) ** z)

    def set_weights(self, axis):
        """Return ``[(weight, AxisFit), ...]`` of the term sets (:func:`.averaging.weights`)."""
        if axis not in self._weights:
            self._weights[axis] = weights(self.fits[axis])
        return self._weights[axis]

    def averaged_interval(self, axis, term, level=CI_LEVEL, selective=True):
        """
        Return a term's main-parameter interval at ``level`` averaged over the term sets.

        ``selective=False`` leaves out the post-selection lower end (what a longer record, in
        which the term stands clear of its threshold, keeps of the width: the advisor's).
        """
        fit = self.fits[axis]
        scale = fit.adequacy.scale if fit.adequacy is not None else 1.0
        selection = selection_gain(fit, term) if selective else None
        return averaged_interval(self.set_weights(axis), term, level, fit, scale, selection)

    def alarm_low(self, axis, term):
        """
        Return the lower end a budget alarm on ``term`` rests on (SI; NaN: not resolved).

        The lowest of its 68.3 % interval's lower end (:meth:`interval`), those of the open
        term sets' own fits (:meth:`alternatives`), and those of the resolved terms refitted
        with each term not resolved held at the largest size the data allow at that level
        (the profile limit at delta chi^2 = 1): a budget is missed only when no term set the
        data cannot reject, and no size of a term they do not resolve, puts the lower end
        below it (docs/online.md, Health).
        """
        low = self.interval(axis, term)[0]
        if not math.isfinite(low):
            return low
        return min(low, self.alarm_lows(axis).get(term, low))

    def alarm_lows(self, axis):
        """Return {resolved term: its lowest lower end over open sets and held terms} (cached)."""
        fit = self.fits.get(axis)
        if fit is None or fit.problem is None:
            return {}
        if fit.alarm_lows is None:
            resolved = [t for t in fit.terms if t in self.resolved(axis)]
            others = [fit.candidate_fits.get(frozenset(names))
                      for names in self.alternatives(axis)[1:]]
            problem = fit.problem
            names = [t for t in fit.terms if t in resolved or t in problem.fixed]
            for held in self.limits(axis):  # each refitted once, for every resolved term
                # (delta chi^2 = 1: the size the data allow at the interval's 68.3 %)
                size = problem_upper_limit(problem, names + [held], held, 1.0)
                if math.isfinite(size) and size > 0:
                    others.append(fit_terms(problem.with_offset(
                        size ** 2 * problem.column(held)), names, profile_intervals=False))
            fit.alarm_lows = {}
            for term in resolved:
                main = TERMS[term].params[0]
                # a fit that pins the term at zero allows none of it: its lower end is 0
                fit.alarm_lows[term] = min([other.intervals[term][main][0]
                                            if term in other.intervals else 0.0
                                            for other in others if other is not None],
                                           default=math.inf)
        return fit.alarm_lows

    def alternatives(self, axis):
        """
        Term sets the data of ``axis`` cannot reject, the selected one first.

        Every candidate set whose criterion is within :data:`.axis.ALTERNATIVE_MARGIN`
        of the best (see there); ``[selected]`` when the terms were named, not selected.
        """
        fit = self.fits.get(axis)
        if fit is None or not fit.terms:
            return []
        selected, rejected = list(fit.terms), fit.rejected_sets
        return [selected] + [list(names) for names in hadamard_check.open_sets(fit.candidates)
                             if set(names) != set(selected) and frozenset(names) not in rejected]

    def resolved(self, axis):
        """
        Return the terms of ``axis`` the record resolves: those every open term set holds.

        The others are reported as upper limits (:meth:`upper_limit`; docs/method.md
        section 11).  Named terms (``fit_noise_model(terms=...)``) are all resolved.
        """
        sets = self.alternatives(axis)
        return set.intersection(*(set(s) for s in sets)) if sets else set()

    def unresolved(self, axis):
        """Return the selected set's terms of ``axis`` that are not resolved (:meth:`resolved`)."""
        fit = self.fits.get(axis)
        return [] if fit is None else [t for t in fit.terms if t not in self.resolved(axis)]

    def rejected(self, axis):
        """
        Term sets the Allan fit left open but another curve contradicts (JSON-ready).

        ``[{'terms': [...], 'by': curve, ...}]``; so far only the Hadamard check of a rate
        random walk against a rate ramp (:mod:`.hadamard_check`, curve ``'ohdev'``, with its
        ``gain``, ``walk_min`` and ``walk_max``), run when :func:`fit_noise_model` is given
        the OHDEV curve.
        """
        fit = self.fits.get(axis)
        return [{'terms': e['terms'], 'by': e['curve'],
                 **{k: v for k, v in e.items() if k not in ('terms', 'curve', 'rejected')}}
                for e in (fit.evidence if fit is not None else []) if e['rejected']]

    def decided_by(self, axis):
        """
        Name the curves that decided the term set of ``axis``; None while alternatives remain.

        ``'oadev'`` when the Allan fit alone leaves no alternative, ``'oadev+ohdev'`` when the
        Hadamard curve rejected the last ones; None when the terms were named or nothing was
        fitted.
        """
        fit = self.fits.get(axis)
        if (fit is None or not fit.terms or not fit.candidates
                or len(self.alternatives(axis)) > 1):
            return None
        curves = ['oadev'] + sorted({e['curve'] for e in fit.evidence if e['rejected']})
        return '+'.join(curves)

    def upper_limit(self, axis, term):
        """
        95 % upper limit of a term the record does not resolve on ``axis`` (SI, cached).

        The largest profile limit (:func:`.axis.upper_limit`) over the best :data:`LIMIT_SETS`
        open term sets, the term added where a set lacks it: it holds whichever open set is
        the sensor's.  NaN if the term is resolved, nothing was fitted, or it is not bounded.
        """
        fit = self.fits.get(axis)
        if fit is None:
            return math.nan
        if term not in fit.upper_limits:
            limits = []
            if fit.problem is not None and fit.terms and term not in self.resolved(axis):
                for names in self.alternatives(axis)[:LIMIT_SETS]:
                    names = list(names) + ([] if term in names else [term])
                    limits.append(float(problem_upper_limit(fit.problem, names, term)))
            fit.upper_limits[term] = (max(limits) if limits and all(
                math.isfinite(v) for v in limits) else math.nan)
        return fit.upper_limits[term]

    def limits(self, axis):
        """
        Return ``{term: 95 % upper limit}`` (SI; NaN: not bounded) of the IEEE terms not resolved.

        In :data:`~imu_allan.core.units.IEEE_TERMS` order (:meth:`upper_limit`), {} unfitted.
        """
        if axis not in self.fits or not self.fits[axis].terms:
            return {}
        resolved = self.resolved(axis)
        return {t: self.upper_limit(axis, t) for t in IEEE_TERMS if t not in resolved}

    def limit_report(self, axis):
        """Return ``{term: {upper_limit, level, unit, open, conventional}}`` (:meth:`limits`)."""
        held = set().union(*(set(s) for s in self.alternatives(axis)))
        out = {}
        for term, limit in self.limits(axis).items():
            finite = math.isfinite(limit)
            conv, conv_unit = conventional(axis, term, limit) if finite else (None, None)
            out[term] = {'upper_limit': limit if finite else None, 'level': LIMIT_LEVEL,
                         'unit': si_unit(axis, term), 'open': term in held,
                         'conventional': {'upper_limit': conv, 'unit': conv_unit}}
        return out

    def adequacy(self, axis):
        """Return the adequacy test of ``axis`` (:class:`.adequacy.Adequacy`), None if unfitted."""
        fit = self.fits.get(axis)
        return None if fit is None else fit.adequacy

    def tau_range(self, axis):
        """Return the averaging times fitted on ``axis`` (:class:`.tau_range.TauRange`) or None."""
        fit = self.fits.get(axis)
        return None if fit is None else fit.tau_range

    def model_avar(self, axis, tau):
        """Return the AVAR at ``tau`` (s) of the curve the fit drew: the selected set, lines."""
        fit = self.fits.get(axis)
        if fit is None:
            return _terms.model_avar({}, tau, self.rate_hz)
        lines = sum(_nuisance_avar(fit, tau), 0.0)
        return _terms.model_avar(fit.terms, tau, self.rate_hz) + lines

    def term_report(self, axis):
        """JSON-ready ``{term: {value, ci, unit, time, conventional}}`` for one axis."""
        out = {}
        for term, params in self.model.terms.get(axis, {}).items():
            main = TERMS[term].params[0]
            lo, hi = self.intervals[axis][term][main]
            conv, conv_unit = conventional(axis, term, params[main])
            entry = {'value': params[main], 'ci': [lo, hi], 'unit': si_unit(axis, term),
                     'time': 'continuous',
                     'conventional': {'value': conv, 'unit': conv_unit,
                                      'ci': [conventional(axis, term, lo)[0],
                                             conventional(axis, term, hi)[0]]}}
            for extra in params:
                if extra != main:
                    entry[extra] = {'value': params[extra],
                                    'ci': list(self.intervals[axis][term][extra]),
                                    'unit': TERMS[term].param_unit(axis, extra)}
            out[term] = entry
        return out


def fit_noise_model(result, terms=None, axes=None, deviations=None, processing=None,
                    tau_range=None):
    """
    Fit noise terms to every axis of an :class:`~imu_allan.core.allan.estimate.AllanResult`.

    ``terms``: a sequence (or comma-separated string) of
    :data:`~imu_allan.core.units.ALL_TERMS` fitted on every axis; default: the IEEE terms
    selected by chi^2 + 2 k ln T.  ``axes``: those to fit (default all).  ``deviations``:
    ``{kind: DeviationResult}`` of the same record; with ``'ohdev'`` and a selection, the
    Hadamard check (:mod:`.hadamard_check`).  ``processing``: ``{axis: Processing}``
    (:class:`.tau_range.Processing`, measured or known from the device): the fit leaves out
    the averaging times it shapes and fits its lines (:mod:`.tau_range`); without it every
    usable averaging time is fitted.  ``tau_range``: (lo, hi) s, fit only these averaging
    times on every axis.  Returns a :class:`FittedModel`.
    """
    if isinstance(terms, str):
        terms = [t.strip() for t in terms.split(',') if t.strip()]
    fits = {}
    duration = result.n_samples / result.rate_hz
    for axis in (axes or result.axes):
        j = result.axis_index(axis)
        tau, avar, edf, alpha = result.tau, result.avar[:, j], result.edf[:, j], result.alpha[:, j]
        proc = (processing or {}).get(axis)
        span = _span(tau, avar, edf, result.rate_hz, proc, tau_range)
        fit = fit_axis(tau, avar, edf, alpha, result.rate_hz, terms, duration, span)
        ohdev = (deviations or {}).get('ohdev')
        if (terms is None and ohdev is not None and axis in ohdev.axes and fit.terms
                and hadamard_check.applies(fit)):
            hadamard = hadamard_check.hadamard_problem(ohdev, axis, fit.coef, span.lo)
            if hadamard is not None:
                fit = hadamard_check.decide(fit, fit.problem, hadamard)
        _assess(fit, result.rate_hz, proc)
        if terms is None:
            fit = _bounded_drift(fit, result.rate_hz, proc)
        fits[axis] = fit
    return FittedModel(fits, result.rate_hz, result)


def _span(tau, avar, edf, rate_hz, processing, tau_range):
    """Return the :class:`TauRange` of one axis: its usable points, cut as asked or chosen."""
    ok = usable_points(avar, edf)
    if not ok.any():
        return TauRange(math.nan, math.nan)
    span = choose(processing, tau[ok], avar[ok], edf[ok], rate_hz)
    if tau_range is not None:  # asked for: the span, with the shapes the processing gives
        span.lo, span.hi = max(tau_range[0], tau[ok][0]), min(tau_range[1], tau[ok][-1])
        span.limited_by = 'asked' if tau_range[0] > tau[ok][0] else None
    return span


def _assess(fit, rate_hz, processing):
    """Set ``fit.adequacy`` (and widen the intervals of a model the curve rejects)."""
    problem = fit.problem
    if problem is None or not fit.terms:
        return
    tau = problem.tau
    columns = np.column_stack([
        params[TERMS[name].params[0]] ** 2
        * problem.column(name, params.get(TERMS[name].position) if TERMS[name].position
                         else None)
        for name, params in fit.terms.items()])
    nuisance = _nuisance_avar(fit, tau, deficit=True)
    if nuisance:
        columns = np.column_stack([columns] + nuisance)
    names = list(fit.terms)
    model = columns.sum(axis=1)
    ramp, drift, drift_sd = None, None, None
    if 'rate_ramp' in names:
        ramp = columns[:, names.index('rate_ramp')]
        t_rec = problem.duration_s
        if t_rec:  # the estimator's cross term R tau^2 D / (T - 2 tau), D the noise's drift
            drift = tau * tau / np.maximum(t_rec - 2.0 * tau, tau)
            drift_sd = ramp_cross_sd(problem, fit.coef) / model
    fit.adequacy = assess(tau, problem.avar, problem.edf, problem.corr, model, columns,
                          _namer(processing, tau), ramp, drift, drift_sd)
    widen(fit, fit.adequacy.scale)


def _nuisance_avar(fit, tau, deficit=False):
    """
    Return the AVAR (per tau) of each nuisance line the fit carries, a list of arrays.

    ``deficit``: also the filter's deficit where it is a nuisance column (for the fitted
    averaging times only: below the filter's reach its closed form does not hold, so the drawn
    model leaves it out); a known filter's is in white noise's own column.
    """
    out = [a * a * sinusoid_shape(tau, f) for f, a in fit.lines.items()]
    if deficit and fit.filter_deficit and fit.problem.deficit_fitted:
        out.append(-fit.filter_deficit / (fit.problem.rate_hz * np.asarray(tau) ** 2))
    return out


#: The Gauss-Markov hump is tried where the adequacy test's p falls below this ...
DRIFT_TRIAL_P = 0.05
#: ... and kept when it lowers the test's chi^2 by more than the 99 % quantile of chi^2 with
#: the parameters it adds (sigma and tau_c: 2; 1 where it replaces a random walk or ramp).
DRIFT_GAIN = {1: 6.63, 2: 9.21}


def _bounded_drift(fit, rate_hz, processing):
    """
    Try a Gauss-Markov hump where the selected IEEE terms bend away from the curve.

    Where the selection holds a random walk and the adequacy test's p is below
    :data:`DRIFT_TRIAL_P`: the selected set plus a Gauss-Markov term, and the same with the
    random walk (and a ramp) replaced by it; the one the test likes best is kept if it lowers
    the test's chi^2 by more than :data:`DRIFT_GAIN` (docs/method.md section 10, "Bounded
    drifts").
    """
    if (fit.adequacy is None or not fit.adequacy.p < DRIFT_TRIAL_P
            or 'rate_random_walk' not in fit.terms
            or 'gauss_markov' in fit.terms or not fit.candidates):
        return fit
    problem = fit.problem
    names = list(fit.terms)
    without = [n for n in names if n not in ('rate_random_walk', 'rate_ramp')]
    best, best_gain = fit, 0.0
    for trial in {tuple(names), tuple(without)}:
        new = fit_terms(problem, trial + ('gauss_markov',))
        if 'gauss_markov' not in new.terms:
            continue
        _assess(new, rate_hz, processing)
        added = len(new.terms) + 1 - len(names)  # tau_c counts
        gain = (fit.adequacy.chi2 - new.adequacy.chi2) / STATISTIC_SCALE
        if added in DRIFT_GAIN and gain > DRIFT_GAIN[added] and gain > best_gain:
            best, best_gain = new, gain
    if best is not fit:
        best.candidates = [(best.chi2, tuple(best.terms))]
        best.considered = fit.considered
    return best


def _namer(processing, tau):
    """Return a namer of what bends a misfit span (lo, hi, ratio), from the sensor's facts."""
    def name(lo, hi, ratio):
        def near(t):  # a bump peaking within a factor 3 of the span
            return lo / 3.0 <= t <= hi * 3.0
        if processing is not None:
            for f, _ in sorted(processing.lines, key=lambda ln: -ln[1]):
                if near(_terms.TERMS['sinusoid'].peak_ratio / f):
                    return f'a {f:.3g} Hz line'
            for f_lo, f_hi, _ in processing.humps:
                if near(_terms.TERMS['sinusoid'].peak_ratio / f_lo):
                    return f'a resonance at {f_lo:.3g}-{f_hi:.3g} Hz'
            if lo <= tau[0] and processing.filter_moment > 0 and ratio < 1.0:
                return "the sensor's filter"
        # a span in the last third of the curve (log tau) that reaches its end: the drift
        if hi >= tau[-1] and lo >= tau[0] * (tau[-1] / tau[0]) ** (2.0 / 3.0):
            return ('more drift than the model (random walk, ramp or temperature)' if ratio > 1
                    else 'a bounded drift the model lacks (Gauss-Markov or an oscillation)')
        return None
    return name
