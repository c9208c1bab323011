"""
The recording advisor: how much longer to record until each noise term is known well enough.

ROS-free.  For every axis and resolved term: the relative precision now (68.3 % half-width /
value) and the additional recording, under the same conditions, until it meets a target; the
open term sets the data cannot yet tell apart, with the time until they are; every term not
resolved with its 95 % upper limit and the time until one that large would be resolved.  No
new data needed: the fit's GLS covariance is evaluated on the fitted model's own noise-free
curve for a record of n' samples (its averaging times and EDF), and n' found by guided
bisection in log n' (:mod:`.bisection`).  The method, and what it was measured to predict:
docs/method.md section 7.
"""

import dataclasses
from dataclasses import dataclass, field
import math

import numpy as np

from .averaging import selection_gain

# The fit's own problem set-up (whitening, shapes): the forecast must use exactly the same.
from .axis import (
    ALTERNATIVE_MARGIN,
    coefficient_interval,
    deterministic_index,
    fit_terms,
    Problem,
    ramp_drift_variance,
    selection_penalty,
    shape_columns,
)
from .bisection import bisection, guided, log_ratio
from .bounded_min import bounded_minimum
from .. import terms as _terms
from ..allan.edf import CI_LEVEL, edf_oadev
from ..allan.estimate import (
    DEFAULT_MIN_CLUSTERS,
    DEFAULT_POINTS_PER_DECADE,
    identify_noise,
    min_record,
)
from ..units import ALL_TERMS, IEEE_TERMS, TERM_PARAMETERS
from ...errors import InputError

#: Default targets: relative 68.3 % half-width per term (main parameter; sigma for
#: Gauss-Markov).  The one place these numbers live.
DEFAULT_TARGETS = {'white_noise': 0.02, 'quantization': 0.25, 'bias_instability': 0.10,
                   'rate_random_walk': 0.25, 'rate_ramp': 0.25, 'gauss_markov': 0.25}
#: Accepted range of a target (relative half-width).
TARGET_RANGE = (0.001, 1.0)
#: Longest record considered, as a multiple of the current one.
HORIZON = 1.0e4
#: Bisection steps in log n (10 steps over a factor 1e4: 0.9 % resolution in time).
_BISECTIONS = 10


def parse_targets(text, where='--target'):
    """
    Targets from ``'bias_instability=0.05,white_noise=0.01'`` merged over the defaults.

    Raises :class:`InputError` naming ``where`` for an unknown term, a non-number or a value
    outside :data:`TARGET_RANGE`.
    """
    targets = dict(DEFAULT_TARGETS)
    for item in str(text or '').split(','):
        item = item.strip()
        if not item:
            continue
        term, sep, value = item.partition('=')
        term = term.strip()
        if not sep:
            raise InputError(where, f'{item!r} is not TERM=REL (e.g. bias_instability=0.05)')
        if term not in DEFAULT_TARGETS:
            raise InputError(where, f'unknown term {term!r} (known: '
                                    f'{", ".join(DEFAULT_TARGETS)})')
        try:
            rel = float(value)
        except ValueError:
            raise InputError(where, f'{term}: {value.strip()!r} is not a number') from None
        if not TARGET_RANGE[0] <= rel <= TARGET_RANGE[1]:
            raise InputError(where, f'{term}: relative half-width {rel:g} outside '
                                    f'[{TARGET_RANGE[0]:g}, {TARGET_RANGE[1]:g}]')
        targets[term] = rel
    return targets


@dataclass
class TermAdvice:
    """
    A resolved term of one axis: its precision now and the additional time to its target, s.

    ``more_s`` is 0 when the target is met and None when no prediction is possible
    (``reason`` says why).
    """

    rel_halfwidth: float
    more_s: float
    reason: str = None


@dataclass
class Limit:
    """
    A term the record does not resolve on one axis: its 95 % upper limit and when it would be.

    ``upper_limit`` (SI, continuous-time; None: the data do not bound it); ``in_open_set``:
    some open term set holds it (the data cannot tell whether it is there), else none does;
    ``more_s``: additional recording after which a term as large as its upper limit would be
    resolved, None with a ``reason`` when no record within reach would resolve it.
    """

    upper_limit: float
    more_s: float
    reason: str = None
    in_open_set: bool = False


@dataclass
class Unresolved:
    """
    The term sets the data of one axis cannot yet tell apart, and the time until they can.

    ``sets``: the open sets, the selected one first (:meth:`.FittedModel.alternatives`);
    ``terms``: the terms in which they differ; ``more_s``: additional recording until every
    other set is told from the selected one (None: not within reach, ``reason``).
    """

    axis: str
    terms: tuple
    more_s: float
    reason: str = None
    sets: tuple = ()


@dataclass
class Advice:
    """Advice for a whole record: targets, resolved terms, open sets and limits per axis."""

    targets: dict
    duration_s: float
    #: axis -> {term: TermAdvice}: the resolved terms
    axes: dict = field(default_factory=dict)
    #: one entry per axis whose open term sets differ
    unresolved: list = field(default_factory=list)
    #: axis -> {term: Limit}: the IEEE terms not resolved
    limits: dict = field(default_factory=dict)
    #: axes the motion verdict calls moving (set by the report): no noise measurement
    moving: list = field(default_factory=list)
    #: axes whose model the adequacy test rejects (:mod:`.adequacy`): their precision
    #: figures are those of a model that does not describe the curve, never "precise"
    inadequate: list = field(default_factory=list)

    @property
    def record_more_s(self):
        """Longest finite additional time over the resolved terms and open sets, s."""
        times = [a.more_s for terms in self.axes.values() for a in terms.values()
                 if a.more_s is not None]
        times += [u.more_s for u in self.unresolved if u.more_s is not None]
        return max(times, default=0.0)


def analysis_grid(points_per_decade=DEFAULT_POINTS_PER_DECADE,
                  min_clusters=DEFAULT_MIN_CLUSTERS, m_max=None):
    """
    Return ``grid(n)``: averaging factors of a record of n samples, as dense as ``analyze``'s.

    10^(k / points_per_decade) up to n / min_clusters and that longest factor itself: the
    density and span of :func:`~.allan.tau_grid`, anchored at m = 1 so that records of
    different length share their factors (the sampled flicker shape is cached per factor).
    """
    def grid(n):
        top = int(n // min_record(min_clusters))
        top = top if m_max is None else min(top, int(m_max))
        if top < 1:
            return np.zeros(0, dtype=np.int64)
        k = np.arange(int(math.floor(math.log10(top) * points_per_decade)) + 1)
        ms = np.round(10.0 ** (k / points_per_decade)).astype(np.int64)
        # the longest averaging time itself, as tau_grid has it: it informs slow terms most
        ms = ms[ms < top * 10.0 ** (-0.5 / points_per_decade)]
        return np.unique(np.append(ms, top))
    return grid


def factor_grid_of(ms, min_clusters):
    """``grid(n)`` for a fixed factor list (the online estimator): m <= n / min_clusters."""
    ms = np.asarray(ms, dtype=np.int64)
    return lambda n: ms[ms * int(min_clusters) <= n]


def _n_params(names):
    return sum(len(TERM_PARAMETERS[t]) for t in names)


def _nonlinear(axis_terms):
    return {t: p[TERM_PARAMETERS[t][1]] for t, p in axis_terms.items()
            if len(TERM_PARAMETERS[t]) > 1}


class _Forecast:
    """Noise-free problems of records of n samples from a model curve (cached by n)."""

    def __init__(self, rate_hz, grid, span=None):
        self.rate_hz = rate_hz
        self.grid = grid
        # the fit's own span (fit.tau_range: lower end, line, filter), open at the long end
        self.span = None if span is None else dataclasses.replace(span, hi=math.inf)
        self._cache = {}
        self._gaps = {}  # a crossing search starts where its scale was taken: asked twice

    def problem(self, n, axis_terms, key):
        """Return the fit's problem for a record of ``n`` samples whose AVAR is the model's."""
        cached = self._cache.get((n, key))
        if cached is not None:
            return cached
        ms = self.grid(n)
        if ms.size < 2:
            return None
        tau = ms / self.rate_hz
        avar = _terms.model_avar(axis_terms, tau, self.rate_hz)
        if self.span is not None and 'white_noise' in axis_terms:  # as the fit's white column
            avar = avar - axis_terms['white_noise']['value'] ** 2 * self.span.known_deficit(
                tau, self.rate_hz)
        alpha = identify_noise(tau, avar[:, None])[:, 0]
        edf = np.array([edf_oadev(int(a), int(m), int(n) + 1) for a, m in zip(alpha, ms)])
        problem = Problem(tau, avar, edf, alpha, self.rate_hz, n / self.rate_hz, self.span,
                          expected=True)
        self._cache[(n, key)] = problem
        return problem

    def rel_halfwidths(self, n, axis_terms):
        """Predicted relative half-width of every term of ``axis_terms`` at n samples."""
        problem = self.problem(n, axis_terms, 'fit')
        if problem is None or problem.tau.size < len(axis_terms):
            return {}
        names = list(axis_terms)
        shapes = shape_columns(problem, names, _nonlinear(axis_terms))
        ramp = deterministic_index(names)
        det = 0.0 if ramp is None else shapes[:, ramp] * axis_terms['rate_ramp']['value'] ** 2
        g = problem.whiten(problem.avar, shapes, det)
        try:
            cov = np.linalg.inv(g.T @ g)
        except np.linalg.LinAlgError:
            return {}
        if ramp is not None:  # the noise's own drift, as the fit adds it
            cov[ramp, ramp] += ramp_drift_variance(problem, {
                t: p['value'] ** 2 for t, p in axis_terms.items() if 'value' in p})
        out = {}
        for j, term in enumerate(names):
            value = axis_terms[term][TERM_PARAMETERS[term][0]]
            sd = math.sqrt(max(cov[j, j], 0.0))
            out[term] = math.inf
            if value > 0:  # the fit's 68.3 % interval of sqrt(c)
                c = value * value
                lo, hi = coefficient_interval(c, sd * sd, CI_LEVEL, term == 'rate_ramp')
                out[term] = (hi - lo) / (2.0 * math.sqrt(c))
        return out

    def criterion_gap(self, n, truth, key, other_names, start=None):
        """
        Noise-free criterion of ``other_names`` fitted to the ``truth`` curve minus truth's.

        ``start`` holds starting values of nonlinear parameters (tau_c) of ``other_names``.
        """
        memo = (n, key, tuple(other_names), tuple(sorted((start or {}).items())))
        if memo not in self._gaps:
            problem = self.problem(n, truth, key)
            if problem is None:
                return 0.0
            self._gaps[memo] = (_best_chi2(problem, other_names, start or {},
                                           _nonlinear(truth))
                                + (_n_params(other_names) - _n_params(truth))
                                * selection_penalty(problem))
        return self._gaps[memo]


def _best_chi2(problem, names, start, hold=None):
    """
    Smallest GLS chi^2 of ``names`` (one nonlinear parameter profiled near ``start``).

    A position the problem fixes (a line's frequency) stays fixed; the problem's nuisance
    lines are fitted alongside, as in the fit.  With two free positions (a named sinusoid
    beside a Gauss-Markov) the first one ``start`` lacks is profiled and the other held: at
    its start, else at ``hold`` (the truth curve's positions), else mid-span.
    """
    fixed = {t: p for t, p in problem.fixed.items() if t in names}
    nonlinear = [t for t in names if len(TERM_PARAMETERS[t]) > 1 and t not in fixed]

    def solve(positions):
        return problem.solve(problem.with_nuisance(shape_columns(problem, names, positions)),
                             deterministic=deterministic_index(names))[1]
    if not nonlinear:
        return solve(fixed)
    name = next((t for t in nonlinear if not start.get(t)), nonlinear[0])
    middle = math.sqrt(problem.tau[0] * problem.tau[-1])  # s; a frequency: 1 / middle
    for t in nonlinear:
        if t != name:
            fixed[t] = (start.get(t) or (hold or {}).get(t)
                        or (1.0 / middle if t == 'sinusoid' else middle))
    centre = math.log(start.get(name) or middle)

    def chi2(log_p):
        return solve({**fixed, name: math.exp(log_p)})
    return min(bounded_minimum(chi2, centre - 2.0, centre + 2.0, xatol=0.02)[1], chi2(centre))


def _samples(log_n):
    return int(round(math.exp(log_n)))


def bisection_crossing(ok, n0, n_max):
    """
    Smallest n in [n0, n_max] with ``ok(n)`` (monotone) by bisection in log n; None: not n_max.

    The reference of :func:`_crossing` (same n, more evaluations); a generator that yields
    between evaluations, as every search here.
    """
    if ok(n0):
        return n0
    yield
    if not ok(n_max):
        return None
    _, hi = yield from bisection(lambda x: ok(_samples(x)), math.log(n0), math.log(n_max),
                                 _BISECTIONS)
    return int(math.ceil(math.exp(hi)))


def _crossing(evaluate, n0, n_max, slope):
    """
    Return the n of :func:`bisection_crossing` with ``ok(n) = evaluate(n)[0]``, sooner.

    ``evaluate(n)``: ``(ok, level)`` as :func:`~.bisection.guided` takes them; ``slope``: the
    level's expected growth per unit of log n, for the first guess.  n_max (the costliest
    forecast) is evaluated only when the crossing is not found below it.
    """
    return (yield from _crossing_point(evaluate, n0, n_max, slope))[0]


def _crossing_point(evaluate, n0, n_max, slope):
    """
    :func:`_crossing`'s search; return ``(n, x)``: that n, and the log n where ok holds.

    ``x`` is the upper end of bisection's last cell (a point of its grid on
    [log n0, log n_max]; log n0 when ok holds at n0), ``(None, None)`` when n_max fails too.
    """
    first = evaluate(n0)
    if first[0]:
        return n0, math.log(n0)
    lo, hi = math.log(n0), math.log(n_max)
    cell = yield from guided(lambda x: evaluate(_samples(x)), lo, hi, _BISECTIONS,
                             (first[1], first[1] + slope * (hi - lo)), key=_samples,
                             hi_known=False)
    return (None, None) if cell is None else (int(math.ceil(math.exp(cell[1]))), cell[1])


def _separated(gap):
    """Return a noise-free criterion gap that exceeds the margin even 1 sd below its mean."""
    return gap - 2.0 * math.sqrt(max(gap, 0.0)) >= ALTERNATIVE_MARGIN


#: The smallest separated gap: g - 2 sqrt(g) = margin at sqrt(g) = 1 + sqrt(1 + margin).
_SEPARATED_GAP = (1.0 + math.sqrt(1.0 + ALTERNATIVE_MARGIN)) ** 2


class _AxisAdvisor:
    """Advice for one axis, computed in small steps (:meth:`steps` is a generator)."""

    def __init__(self, result, fitted, axis, targets, grid, undetected=True):
        self.axis = axis
        self.undetected = undetected
        self.targets = targets
        self.fitted = fitted
        self.fit = fitted.fits[axis]
        # the measured curve as the fit saw it (span, fixed lines)
        self.problem = self.fit.problem
        self.rate_hz = result.rate_hz
        self.n = int(result.n_samples)
        self.forecast = _Forecast(result.rate_hz, grid, self.fit.tau_range)
        self.terms = {}
        self.limits = {}
        self.unresolved = None

    def _more_s(self, n):
        return None if n is None else max(n - self.n, 0) / self.rate_hz

    def steps(self):
        """Yield one forecast evaluation per step; fills the terms, open sets and limits."""
        n_max = int(self.n * HORIZON)
        resolved = self.fitted.resolved(self.axis)
        yield from self._precision({t: p for t, p in self.fit.terms.items() if t in resolved},
                                   n_max)
        yield from self._open_sets(n_max)
        yield from self._not_resolved(resolved, n_max)

    def _precision(self, axis_terms, n_max):
        """Relative half-width now and the time to each resolved term's target."""
        for term, params in axis_terms.items():
            target = self.targets.get(term)
            if target is None:
                continue
            main = TERM_PARAMETERS[term][0]
            value = params[main]
            lo, hi = self.fit.intervals[term][main]
            rel = (hi - lo) / (2.0 * value) if value > 0 else math.inf
            if rel <= target:
                self.terms[term] = TermAdvice(rel, 0.0)
                continue

            # Scaled so that the forecast at the current length is the fit's half-width
            # averaged over the term sets (they differ by the grid, the noise identification
            # and the averaging); the post-selection part of the width is the record's now,
            # not a longer one's, where the term stands clear of its threshold.
            now = self.forecast.rel_halfwidths(self.n, self.fit.terms).get(term, math.nan)
            lo, hi = self.fitted.averaged_interval(self.axis, term, selective=False)
            scale = (hi - lo) / (2.0 * value) / now if now > 0 else 1.0

            def evaluate(n, term=term, target=target, scale=scale):
                forecast = self.forecast.rel_halfwidths(n, self.fit.terms)
                rel = scale * forecast.get(term, math.inf)
                return rel <= target, log_ratio(target, rel)
            # the half-width falls as n^-1/2
            n_hit = yield from _crossing(evaluate, self.n, n_max, 0.5)
            if n_hit is not None:  # and the choice of terms must have stopped widening it
                n_hit = max(n_hit, self._clear_of_threshold(term))
            self.terms[term] = TermAdvice(rel, self._more_s(n_hit), None if n_hit else
                                          f'not reached within {HORIZON:g} x the record')

    def _clear_of_threshold(self, term):
        """
        Return the samples after which a resolved term's interval stops carrying its selection.

        The post-selection lower end (:func:`.averaging.selective_lower`) matters while the
        gain G (growing as n) is near the G* that resolves the term; from
        sqrt(G) = sqrt(G*) + 2.5 on it moves the interval by under 1 %.
        """
        gains = selection_gain(self.fit, term)
        if gains is None or not gains[0] > 0:
            return self.n
        gain, needed = gains
        return int(math.ceil(self.n * max((math.sqrt(needed) + 2.5) ** 2 / gain, 1.0)))

    def _latest(self, ns):
        """``(more_s, reason)`` of the latest of several sample counts (None: never)."""
        if any(n is None for n in ns):
            return None, f'not at their fitted sizes within {HORIZON:g} x this record'
        return self._more_s(max(ns, default=self.n)), None

    def _open_sets(self, n_max):
        """
        Time until each open set is told from the selected one; fills :attr:`unresolved`.

        Returns ``[(terms in which the two differ, n or None), ...]``; the rule is
        docs/method.md section 7's (:func:`_separated` in both directions).
        """
        sets = self.fitted.alternatives(self.axis)
        chosen = list(self.fit.terms)
        times = []
        for alt in sets[1:]:
            alt_fit = fit_terms(self.problem, alt, profile_intervals=False)
            yield
            differ = frozenset(chosen) ^ frozenset(alt)
            gap = self._criterion(alt_fit) - self._criterion(self.fit)
            start = _nonlinear(alt_fit.terms)
            # The direction whose fit is linear (no tau_c profiled at every n) is searched
            # first; the other only matters if it separates later (see _pair_time).
            directions = sorted(((self.fit.terms, list(alt), 'fit'),
                                 (alt_fit.terms, chosen, '+'.join(alt))),
                                key=lambda d: any(len(TERM_PARAMETERS[t]) > 1 for t in d[1]))
            n_sep = yield from self._pair_time(directions, gap, start, n_max)
            times.append((differ, n_sep))
        if times:
            more, reason = self._latest([n for _, n in times])
            differ = sorted(set().union(*(d for d, _ in times)), key=ALL_TERMS.index)
            self.unresolved = Unresolved(self.axis, tuple(differ), more, reason,
                                         tuple(tuple(s) for s in sets))
        return times

    def _criterion(self, fit):
        return fit.chi2 + len(fit.terms) * self.fit.selection_penalty

    def _pair_time(self, directions, crit_gap, start, n_max):
        """
        Return the samples until the gap separates in every direction (None: not by n_max).

        ``directions``: ``(truth, names, key)``, each set taken as the truth and fitted with
        the other.  The time is the latest of theirs, so a direction separated already at the
        latest time so far (a point of the same bisection grid) is not searched, and none is
        after one that never separates.
        """
        latest, at = None, None
        for truth, names, key in directions:
            # If the noise-free gap says "separated" already, the data were unlucky: grow the
            # measured gap as the forecast grows instead (never 0 for an open set).
            gap0 = self.forecast.criterion_gap(self.n, truth, key, names, start)
            scale = max(abs(crit_gap), 1.0) / gap0 if _separated(gap0) else 1.0

            def evaluate(n, truth=truth, names=names, key=key, scale=scale):
                gap = scale * self.forecast.criterion_gap(n, truth, key, names, start)
                return _separated(gap), log_ratio(gap, _SEPARATED_GAP)
            if at is not None:
                yield  # (one forecast evaluation per step: gap0 was one)
                if evaluate(_samples(at))[0]:
                    continue
            # the noise-free gap grows as n
            n_sep, x = yield from _crossing_point(evaluate, self.n, n_max, 1.0)
            if n_sep is None:
                return None
            if latest is None or n_sep > latest:  # (always, if ok is monotone)
                latest, at = n_sep, x
        return latest

    def _not_resolved(self, resolved, n_max):
        """
        Upper limit of each IEEE term not resolved, and when one that large would be.

        The term at its upper limit beside the selected set's other terms is the truth of a
        new record, resolved once every set that could stand in for it (:meth:`_stand_ins`)
        is told from it by :func:`_separated` (docs/method.md section 7).
        ``undetected=False``: only the terms an open set holds.
        """
        sets = self.fitted.alternatives(self.axis)
        held = set().union(*(set(s) for s in sets))
        # the terms the selection considers (quantization is left out beside a filter)
        chosen = set(self.fit.considered or self.fit.terms)
        for term in IEEE_TERMS:
            in_open = term in held
            if term in resolved or not (in_open or self.undetected):
                continue
            limit = self.fitted.upper_limit(self.axis, term)  # cached: exports use it too
            limit = limit if math.isfinite(limit) else None
            yield
            if limit is None or term not in chosen:
                self.limits[term] = Limit(limit, None, 'no upper limit from these data'
                                          if limit is None else "the sensor's processing has "
                                          'its shape: not fitted', in_open_set=in_open)
                continue
            base = [t for t in self.fit.terms if t != term]
            truth = {**{t: self.fit.terms[t] for t in base}, term: {'value': limit}}
            key = 'with_' + term
            if not self.forecast.criterion_gap(self.n, truth, key, base) + self._penalty(
                    self.n, truth, key) > 0:
                self.limits[term] = Limit(limit, None, 'the term does not change the model '
                                                       'curve', in_open_set=in_open)
                continue
            n_hit = yield from self._told_from(truth, key, self._stand_ins(term, base, sets),
                                               n_max)
            self.limits[term] = Limit(limit, self._more_s(n_hit), None if n_hit else
                                      f'not resolved within {HORIZON:g} x the record',
                                      in_open_set=in_open)

    def _stand_ins(self, term, base, sets):
        """Return the sets without ``term`` that could take its place (:meth:`_not_resolved`)."""
        one_more = [list(n) for _, n in self.fit.candidates
                    if term not in n and set(base) < set(n) and len(n) == len(base) + 1]
        out = []
        for names in [list(base)] + one_more + [list(s) for s in sets if term not in s]:
            if set(names) not in [set(o) for o in out]:
                out.append(names)
        return out

    def _told_from(self, truth, key, rivals, n_max):
        """Return the samples until ``truth`` is told from every rival set (None: never)."""
        n_hit = self.n
        for rival in rivals:
            def told(n, rival=rival):
                gap = self.forecast.criterion_gap(n, truth, key, rival)
                return _separated(gap), log_ratio(gap, _SEPARATED_GAP)
            # the noise-free gap grows as n; a later rival starts where the last one ended
            n_hit = yield from _crossing(told, n_hit, n_max, 1.0)
            if n_hit is None:
                return None
        return n_hit

    def _penalty(self, n, truth, key):
        problem = self.forecast.problem(n, truth, key)
        return selection_penalty(problem) if problem else 0.0


class StagedAdvice:
    """
    Advice for every fitted axis in short steps (for a node between message drains).

    ``step()`` runs one forecast evaluation; when :attr:`done`, :attr:`advice` holds the
    :class:`Advice`.  :func:`advise` runs all steps at once.  ``undetected=False`` skips the
    upper limits and resolution times of the terms no open set holds (half the work).
    """

    def __init__(self, result, fitted, targets=None, grid=None, undetected=True):
        targets = dict(DEFAULT_TARGETS if targets is None else targets)
        grid = grid or analysis_grid()
        self.advice = Advice(targets, result.n_samples / result.rate_hz)
        self.advice.inadequate = [a for a in fitted.axes
                                  if (ad := fitted.adequacy(a)) is not None and ad.rejected]
        self._axes = [_AxisAdvisor(result, fitted, axis, targets, grid, undetected)
                      for axis in fitted.axes if fitted.fits[axis].terms]
        self._gen = self._run()
        self.done = False

    def _run(self):
        for adv in self._axes:
            yield from adv.steps()
            self.advice.axes[adv.axis] = adv.terms
            self.advice.limits[adv.axis] = adv.limits
            if adv.unresolved is not None:
                self.advice.unresolved.append(adv.unresolved)

    def step(self):
        """Run the next step; return :attr:`done`."""
        if not self.done:
            try:
                next(self._gen)
            except StopIteration:
                self.done = True
        return self.done


def advise(result, fitted, targets=None, grid=None, undetected=True):
    """
    Return the :class:`Advice` for a record's AllanResult and its FittedModel.

    ``targets``: relative 68.3 % half-width per term (default :data:`DEFAULT_TARGETS`);
    ``grid(n)``: averaging factors of a record of n samples (default :func:`analysis_grid`);
    ``undetected``: as :class:`StagedAdvice`.
    """
    staged = StagedAdvice(result, fitted, targets, grid, undetected)
    while not staged.step():
        pass
    return staged.advice
