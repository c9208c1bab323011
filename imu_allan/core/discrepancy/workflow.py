"""The discrepancy workflow: candidates compete, the winner is added, the gap re-measured."""

from dataclasses import dataclass, field
import math

import numpy as np

from .band import ALPHA, effective_count, measure_gap, measured_band, model_band, pool_simulations
from .significance import improvement_test
from ..allan.estimate import allan_deviation, avar_fast
from ..fit import AxisFit, fit_terms
from ..model import ModelError, NoiseModel
from ..simulation.simulate import simulate
from ..terms import model_avar, TERMS
from ..units import ALL_TERMS, AXES, check_terms
from ...errors import InputError

#: Default starting terms: the thesis's own model (white noise + bias instability).
DEFAULT_START = ('white_noise', 'bias_instability')


@dataclass
class Candidate:
    """A candidate effect fitted together with the current terms."""

    effect: str
    fit: AxisFit
    delta_q: float
    k: int
    ic: float
    p_value: float
    significant: bool
    gain: float = 0.0  # (AIC of the current terms - AIC with the candidate) / k


@dataclass
class Step:
    """One accepted addition to an axis's model (JSON-ready through :meth:`to_dict`)."""

    axis: str
    effect: str
    tau_range: tuple
    gap_before: float
    gap_after: float
    parameters: dict
    terms_after: dict
    p_value: float
    excess_slope: float
    candidates: list
    index: int = 0
    excursion: tuple = None
    snapshot: int = 0  # index of the snapshot before the step (the one after is snapshot + 1)
    was_fixed: bool = False  # the axis's terms came from a model file when the step was tried

    def to_dict(self):
        """Contract fields plus the evidence behind the choice."""
        return {'axis': self.axis, 'effect': self.effect,
                'tau_range_s': list(self.tau_range) if self.tau_range else None,
                'gap_before': self.gap_before, 'gap_after': self.gap_after,
                'parameters': self.parameters, 'p_value': self.p_value,
                'excursion_tau_range_s': (list(self.excursion) if self.excursion else None),
                'excess_adev_slope': (None if not math.isfinite(self.excess_slope)
                                      else self.excess_slope),
                'terms_after': {t: dict(p) for t, p in self.terms_after.items()},
                'candidates': self.candidates}


def _excess_slope(tau, y, band, tau_range):
    """Log-log slope of the measured ADEV excess over the model inside the band (NaN if none)."""
    if not tau_range:
        return math.nan
    sel = (tau >= tau_range[0]) & (tau <= tau_range[1])
    excess = np.exp(2.0 * (y - band.center + 0.5 * np.log(band.avar))) - band.avar
    sel &= excess > 0
    if sel.sum() < 3:
        return math.nan
    slope = np.polyfit(np.log(tau[sel]), np.log(excess[sel]), 1)[0]
    return float(slope / 2.0)


def _effect_band(tau, band, axis_terms, effect, rate_hz):
    """Averaging times where ``effect`` moves the model's ln(adev) by more than one spread."""
    if effect not in axis_terms:
        return None
    total = model_avar(axis_terms, tau, rate_hz)
    without = model_avar({t: p for t, p in axis_terms.items() if t != effect}, tau,
                         rate_hz)
    shift = 0.5 * np.log(np.maximum(total, 1e-300) / np.maximum(without, 1e-300))
    sel = np.nonzero(shift > band.sd)[0]
    if sel.size == 0:
        return None
    return float(tau[sel[0]]), float(tau[sel[-1]])


def _param_report(axis, term, fit):
    out = {}
    for pname, value in fit.terms[term].items():
        unit = TERMS[term].param_unit(axis, pname)
        out[pname] = {'value': value, 'unit': unit,
                      'ci': list(fit.intervals[term][pname]),
                      'ci95': list(fit.intervals95[term][pname]),
                      'at_bound': fit.at_bound[term][pname]}
    return out


def _ordered(names):
    """Return the terms ``names`` in the package's order (that of a fit's terms and labels)."""
    return [t for t in ALL_TERMS if t in names]


def _n_params(term):
    return len(TERMS[term].params)


def evaluate_candidates(y, band, gap, rate_hz, current, alpha=ALPHA, fixed=False):
    """
    Fit every effect the axis lacks; return the candidates, best first.

    ``y`` is the measured ln(adev) on ``band``'s averaging times, ``gap`` its
    :func:`~.band.measure_gap`, ``current`` the axis's ``{term: params}``; with ``fixed`` the
    current parameters came from a model file and a pure refit ('recalibration') competes too.
    """
    prob = band.problem(y, rate_hz)
    t_eff = effective_count(prob.corr)
    hints = {t: TERMS[t].position_at_peak(gap.peak_tau) for t in ('gauss_markov', 'sinusoid')}
    base_names = list(current)
    scale = t_eff / band.tau.size
    results = []
    base = fit_terms(prob, _ordered(base_names), init=current) if base_names else None
    q0 = base.chi2 if base else prob.chi2(np.full(band.tau.shape, 1e-300))
    others = [t for t in ALL_TERMS if t not in current]
    n_tests = len(others) + (1 if fixed and base_names else 0)
    for term in others:
        fit = fit_terms(prob, _ordered(base_names + [term]), init=current, hints=hints)
        delta = q0 - fit.chi2
        k = _n_params(term)
        cols = [i for i, (t, _) in enumerate(fit.labels) if t == term]
        ncols = [i for i, (t, _) in enumerate(fit.labels) if t != term]
        p, _ = improvement_test(delta, fit.jac[:, ncols] if ncols else None,
                                fit.jac[:, cols], prob.corr)
        if TERMS[term].position:  # the hump's position was searched over the whole span
            p = min(1.0, p * max(t_eff, 1.0))
        p_adj = min(1.0, p * n_tests)
        results.append(Candidate(term, fit, delta, k, scale * fit.chi2 + 2.0 * k, p_adj,
                                 p_adj < alpha, (scale * delta - 2.0 * k) / k))
    if fixed and base is not None:
        delta = prob.chi2(band.avar) - base.chi2
        p, _ = improvement_test(delta, None, base.jac, prob.corr)
        p_adj = min(1.0, p * n_tests)
        k = sum(_n_params(t) for t in base_names)
        results.append(Candidate('recalibration', base, delta, k, scale * base.chi2 + 2.0 * k,
                                 p_adj, p_adj < alpha, (scale * delta - 2.0 * k) / k))
    # the effect that lowers the (effective) AIC most per added parameter ranks first
    results.sort(key=lambda c: -c.gain)
    return results


@dataclass
class Snapshot:
    """State of every axis in one round (for plots): model terms, band and gap."""

    terms: dict
    bands: dict
    gaps: dict


@dataclass
class DiscrepancyResult:
    """Everything the workflow found; :meth:`to_dict` gives the contract JSON."""

    measured: object
    axes: list
    initial_model: NoiseModel
    final_model: NoiseModel
    steps: list
    initial_gaps: dict
    final_gaps: dict
    snapshots: list
    n_sims: int
    start: str
    notes: list = field(default_factory=list)
    rejected: list = field(default_factory=list)  # steps that raised the gap: not kept

    @property
    def y(self):
        """Measured ln(adev) (T, A)."""
        return np.log(self.measured.adev)

    def effects(self, axis):
        """Names of the effects added to one axis, in order."""
        return [s.effect for s in self.steps if s.axis == axis]

    def to_dict(self):
        """Report dictionary (``discrepancy --json``)."""
        def union(model):
            present = {t for a in self.axes for t in model.terms.get(a, {})}
            return [t for t in ALL_TERMS if t in present]
        m = self.measured
        gaps = {}
        for a in self.axes:
            g0, g1 = self.initial_gaps[a], self.final_gaps[a]
            gaps[a] = {'initial': g0.value, 'final': g1.value,
                       'consistent': g1.consistent, 'p_value': g1.p_value,
                       'threshold': g1.threshold, 'effective_taus': g1.t_eff,
                       'initial_tau_range_s': list(g0.tau_range) if g0.tau_range else None,
                       'final_tau_range_s': list(g1.tau_range) if g1.tau_range else None}
        return {
            'n_samples': int(m.n_samples), 'sample_rate_hz': float(m.rate_hz),
            'duration_s': float(m.n_samples / m.rate_hz), 'start': self.start,
            'initial_terms': union(self.initial_model), 'final_terms': union(self.final_model),
            'initial_model': self.initial_model.to_dict()['axes'],
            'final_model': self.final_model.to_dict()['axes'],
            'steps': [s.to_dict() for s in self.steps],
            'rejected_steps': [{'axis': s.axis, 'effect': s.effect, 'gap_before': s.gap_before,
                                'gap_after': s.gap_after} for s in self.rejected],
            'gap': gaps,
            'method': {'gap': 'sqrt(mean_i z_i^2), z_i = (ln adev_meas - E ln adev_model) / '
                              'sd(ln adev_model)',
                       'consistent_if': f'chi2.sf(gap^2 T_eff, T_eff) >= {ALPHA}',
                       'n_sims': self.n_sims, 'alpha': ALPHA},
            'notes': list(self.notes),
        }


def _simulate_axis(axis_terms, axis, measured, n_sims, rng):
    """ln(adev) of ``n_sims`` simulated runs of one axis through the same estimator (K, T)."""
    model = NoiseModel({axis: axis_terms}, measured.rate_hz)
    runs = np.empty((n_sims, measured.tau.size))
    for k in range(n_sims):
        x = simulate(model, measured.n_samples, measured.rate_hz, seed=rng, axes=[axis])
        # the AVAR kernel of allan_deviation itself, on the measured averaging factors
        runs[k] = 0.5 * np.log(np.maximum(avar_fast(x, measured.m)[:, 0], 1e-300))
    return runs


def _bands(current, axes, measured, n_sims, rng, previous=None):
    """
    Analytic bands of every axis pooled with ``n_sims`` simulated runs.

    Axes whose terms did not change since ``previous`` (a dict of bands) keep their bands:
    re-simulating an unchanged model would only add noise and time.
    """
    bands = {}
    for axis in axes:
        old = (previous or {}).get(axis)
        if old is not None and old[0] == current[axis]:
            bands[axis] = old[1]
            continue
        band = model_band(current[axis], measured.tau, measured.m, measured.n_samples,
                          measured.rate_hz)
        if n_sims > 0:
            band = pool_simulations(band, _simulate_axis(current[axis], axis, measured,
                                                         n_sims, rng))
        bands[axis] = band
    return bands


def two_pass_fit(y, measured, j, names, init=None, fixed=None, ranges=None):
    """
    Fit ``names`` to column ``j``'s ln(adev) ``y`` twice; return ``(problem, fit)``.

    First against the measured curve's own band, then against the band the first fit's model
    implies (the problem returned).  ``init``, ``fixed`` and ``ranges`` are
    :func:`~imu_allan.core.fit.fit_terms`'s; the second pass starts from the first.
    """
    tau, rate, names = measured.tau, measured.rate_hz, _ordered(names)
    first = fit_terms(measured_band(measured, j).problem(y, rate), names, init=init,
                      fixed=fixed, ranges=ranges)
    prob = model_band(first.terms, tau, measured.m, measured.n_samples, rate).problem(y, rate)
    return prob, fit_terms(prob, names, init=first.terms, fixed=fixed, ranges=ranges)


def start_model(measured, axes, terms, alpha=ALPHA):
    """Fit only ``terms`` to every axis (the ``--terms`` start), in the gap's own metric."""
    out = {}
    for axis in axes:
        j = list(measured.axes).index(axis)
        y = np.log(measured.adev[:, j])
        out[axis] = two_pass_fit(y, measured, j, list(terms))[1].terms
    return NoiseModel(out, measured.rate_hz)


@dataclass(frozen=True)
class DiscrepancyOptions:
    """Options of one discrepancy run: :func:`run_discrepancy`'s keywords of the same names."""

    n_sims: int = 4
    seed: int = 0
    max_steps: int = 4
    alpha: float = ALPHA
    points_per_decade: int = 10
    min_clusters: int = 10


@dataclass(frozen=True)
class _Start:
    """The model the workflow starts from and the axes it works on."""

    axes: list  # analysed axes, in the measured curve's order
    model: NoiseModel
    label: str  # DiscrepancyResult.start: 'model' or 'terms:<name>,...'
    fixed: frozenset  # axes whose terms come from a model file (a refit may compete)


def _measure(data, rate_hz, axes, options):
    """Return the measured Allan deviation of rate samples ``data`` (SI) at ``rate_hz`` (Hz)."""
    if data.ndim == 1:
        data = data[:, None]
    axes = tuple(axes) if axes is not None else AXES[:data.shape[1]]
    return allan_deviation(data, rate_hz, points_per_decade=options.points_per_decade,
                           min_clusters=options.min_clusters, axes=axes)


def _usable_axes(measured, notes):
    """Return the measured axes that have noise to compare; note the constant ones."""
    axes = list(measured.axes)
    if measured.tau.size < 6:
        raise ValueError(f'only {measured.tau.size} averaging times: the record is too short '
                         'for a discrepancy analysis')
    dead = [a for j, a in enumerate(axes)
            if not np.all(np.isfinite(measured.adev[:, j]) & (measured.adev[:, j] > 0))]
    if dead:  # a constant (stuck or absent) channel has no noise to compare
        notes.append(f'{", ".join(dead)}: Allan deviation is zero (constant signal): skipped')
        axes = [a for a in axes if a not in dead]
        if not axes:
            raise ValueError('every axis is constant: no noise to analyse')
    return axes


def _starting_point(measured, axes, model, terms, alpha, notes):
    """
    Return the :class:`_Start`: ``model``'s terms as given, else ``terms`` fitted to ``axes``.

    Axes the model states nothing for are left out (with a note); ``terms`` defaults to
    :data:`DEFAULT_START`.
    """
    if model is not None:
        if isinstance(model, dict):
            model = NoiseModel.from_dict(model)
        work_axes = [a for a in axes if model.terms.get(a)]
        skipped = [a for a in axes if a not in work_axes]
        if not work_axes:
            raise ModelError('model: no terms for any axis of the data '
                             f'({", ".join(axes)})')
        if skipped:
            notes.append(f'model has no terms for {", ".join(skipped)}: skipped')
        initial = NoiseModel({a: model.terms[a] for a in work_axes}, measured.rate_hz)
        return _Start(work_axes, initial, 'model', frozenset(work_axes))
    terms = list(terms) if terms else list(DEFAULT_START)
    try:
        check_terms(terms, '--terms')
    except InputError as exc:  # a bad start is a model error, as a bad model file is
        raise ModelError(str(exc)) from None
    return _Start(axes, start_model(measured, axes, terms, alpha), 'terms:' + ','.join(terms),
                  frozenset())


def _choose_winner(candidates):
    """
    Return the candidate to add (None when none is significant).

    The largest AIC gain per added parameter among the significant new effects (``candidates``
    come best first); a pure recalibration of a model file's own terms only when no new effect
    is needed.
    """
    return next((c for c in candidates if c.significant and c.effect != 'recalibration'),
                None) or next((c for c in candidates if c.significant), None)


def _candidate_report(candidates):
    """Return the JSON-ready evidence of every candidate of a step (``Step.candidates``)."""
    return [{'effect': c.effect, 'ic': c.ic, 'aic_gain_per_parameter': c.gain,
             'delta_q': c.delta_q, 'p_value': c.p_value, 'significant': c.significant}
            for c in candidates]


class _Search:
    """
    State of the workflow across rounds: every axis's terms, band and gap, and the steps.

    Each round proposes one step per open axis (:meth:`propose`), then re-measures the bands
    and gaps of the changed axes and takes back the steps that raised their axis's gap
    (:meth:`remeasure`).
    """

    def __init__(self, measured, start, options, notes):
        self.measured = measured
        self.options = options
        self.notes = notes
        self.axes = start.axes
        self.fixed = set(start.fixed)
        cols = [list(measured.axes).index(a) for a in self.axes]
        self.ys = {a: np.log(measured.adev[:, j]) for a, j in zip(self.axes, cols)}
        self.rng = np.random.default_rng(options.seed)
        self.current = {a: dict(start.model.terms.get(a, {})) for a in self.axes}
        self.bands = _bands(self.current, self.axes, measured, options.n_sims, self.rng)
        self.gaps = self._measure_gaps()
        self.initial_gaps = dict(self.gaps)
        self.snapshots = [self._snapshot()]
        self.steps = []
        self.rejected = []
        self.refused = {a: set() for a in self.axes}  # effects whose step raised the gap
        self.open_axes = set(self.axes)

    def _measure_gaps(self):
        """Return every axis's gap to its current band."""
        return {a: measure_gap(self.ys[a], self.bands[a], self.options.alpha)
                for a in self.axes}

    def _snapshot(self):
        """Return the current terms, bands and gaps of every axis (for plots)."""
        return Snapshot({a: dict(self.current[a]) for a in self.axes}, self.bands, self.gaps)

    def run(self):
        """Run up to ``max_steps`` rounds, until no open axis has a significant candidate."""
        for _ in range(self.options.max_steps):
            pending = [s for s in (self.propose(a) for a in self.axes if a in self.open_axes)
                       if s is not None]
            if not pending:
                break
            self.remeasure(pending)

    def propose(self, axis):
        """
        Return the next :class:`Step` of one axis, its model already updated (None: done).

        An axis without a significant candidate is closed.
        """
        tau, rate = self.measured.tau, self.measured.rate_hz
        y, band, g = self.ys[axis], self.bands[axis], self.gaps[axis]
        cands = evaluate_candidates(y, band, g, rate, self.current[axis], self.options.alpha,
                                    axis in self.fixed)
        was_fixed = axis in self.fixed
        self.fixed.discard(axis)
        cands = [c for c in cands if c.effect not in self.refused[axis]]
        winner = _choose_winner(cands)
        if winner is None:
            self.open_axes.discard(axis)
            return None
        params = (_param_report(axis, winner.effect, winner.fit)
                  if winner.effect in winner.fit.terms else
                  {t: _param_report(axis, t, winner.fit) for t in winner.fit.terms})
        shows = _effect_band(tau, band, winner.fit.terms, winner.effect, rate) or g.tau_range
        step = Step(axis, winner.effect, shows, g.value, math.nan, params, winner.fit.terms,
                    winner.p_value, _excess_slope(tau, y, band, g.tau_range),
                    _candidate_report(cands), index=sum(s.axis == axis for s in self.steps) + 1,
                    excursion=g.tau_range, snapshot=len(self.snapshots) - 1,
                    was_fixed=was_fixed)
        self.current[axis] = {t: dict(p) for t, p in winner.fit.terms.items()}
        return step

    def remeasure(self, pending):
        """Re-measure bands and gaps after the ``pending`` steps; keep those that help."""
        previous = {a: (self.snapshots[-1].terms[a], self.bands[a]) for a in self.axes}
        old_gaps = self.gaps
        self.bands = _bands(self.current, self.axes, self.measured, self.options.n_sims,
                            self.rng, previous)
        self.gaps = self._measure_gaps()
        for step in pending:
            step.gap_after = self.gaps[step.axis].value
            if step.gap_after > step.gap_before:
                self._take_back(step, previous[step.axis], old_gaps[step.axis])
            else:
                self.steps.append(step)
        self.snapshots.append(self._snapshot())

    def _take_back(self, step, previous, old_gap):
        """
        Put a step's axis back to its ``previous`` (terms, band) and gap; refuse its effect.

        The refit lowered the fit's Q with the old spread, but against the band of the new
        model the data sit further out: the step is not kept and the axis's next candidate
        gets its turn.
        """
        axis = step.axis
        self.current[axis] = {t: dict(p) for t, p in previous[0].items()}
        self.bands[axis], self.gaps[axis] = previous[1], old_gap
        self.refused[axis].add(step.effect)
        if step.was_fixed:
            self.fixed.add(axis)
        self.rejected.append(step)
        self.notes.append(f'{axis}: adding {step.effect} raised the gap from '
                          f'{step.gap_before:.2f} to {step.gap_after:.2f}: not kept')


def run_discrepancy(data, rate_hz, axes=None, model=None, terms=None, n_sims=4, seed=0,
                    max_steps=4, alpha=ALPHA, points_per_decade=10, min_clusters=10,
                    measured=None):
    """
    Run the discrepancy workflow on rate samples; return a :class:`DiscrepancyResult`.

    ``data`` (n_samples, n_axes) rate samples, SI (rad/s, m/s^2), at ``rate_hz`` (Hz); ``axes``
    their column names (default: the first n_axes of the package axis order).  The start is
    ``model`` (a NoiseModel, parameters as given, e.g. a datasheet budget), else ``terms``
    fitted to the data (default :data:`DEFAULT_START`).  ``n_sims`` simulated runs per round
    are pooled into the spread (0: analytic spread only), drawn from ``seed``; at most
    ``max_steps`` effects are added per axis; ``alpha`` is the significance level for
    "inconsistent" and for adding an effect; ``points_per_decade`` and ``min_clusters`` set the
    estimator's averaging-time grid; ``measured`` (an AllanResult) skips the estimator.
    """
    options = DiscrepancyOptions(n_sims, seed, max_steps, alpha, points_per_decade,
                                 min_clusters)
    data = None if data is None else np.asarray(data, dtype=float)
    if measured is None:
        measured = _measure(data, rate_hz, axes, options)
    notes = []
    start = _starting_point(measured, _usable_axes(measured, notes), model, terms,
                            options.alpha, notes)
    search = _Search(measured, start, options, notes)
    search.run()
    return DiscrepancyResult(measured, search.axes, start.model,
                             NoiseModel(search.current, measured.rate_hz), search.steps,
                             search.initial_gaps, search.gaps, search.snapshots, n_sims,
                             start.label, notes, search.rejected)


def sample_rate(t):
    """Sample rate (Hz) of time stamps ``t`` (s): 1 / the median increasing difference."""
    dt = np.diff(np.asarray(t, dtype=float))
    dt = dt[np.isfinite(dt) & (dt > 0)]
    if dt.size == 0:
        raise ValueError('time stamps do not increase: cannot find the sample rate')
    return 1.0 / float(np.median(dt))


def gap_summary(model, result, alpha=ALPHA):
    """
    Gap per axis and the effect that fits the excess, for online monitoring.

    ``model`` is the reference NoiseModel (e.g. a model file), ``result`` the latest measured
    AllanResult (batch or streaming), ``alpha`` the significance level.  Returns ``{axis:
    {'gap': float, 'effect': str or None, 'consistent': bool, 'p_value': float, 'tau_range_s':
    [lo, hi] or None}}`` for the axes both have; analytic spread only (no simulation), so it
    costs milliseconds per axis.
    """
    out = {}
    for j, axis in enumerate(result.axes):
        axis_terms = model.terms.get(axis)
        if not axis_terms:
            continue
        ok = np.isfinite(result.adev[:, j]) & (result.adev[:, j] > 0)
        if ok.sum() < 6:
            continue
        tau, ms = result.tau[ok], np.asarray(result.m)[ok]
        y = np.log(result.adev[ok, j])
        band = model_band(axis_terms, tau, ms, int(result.n_samples), result.rate_hz)
        gap = measure_gap(y, band, alpha)
        effect = None
        if not gap.consistent:
            cands = evaluate_candidates(y, band, gap, result.rate_hz, axis_terms, alpha,
                                        fixed=True)
            winner = _choose_winner(cands)
            if winner is not None:
                effect = winner.effect
        out[axis] = {'gap': gap.value, 'effect': effect, 'consistent': gap.consistent,
                     'p_value': gap.p_value,
                     'tau_range_s': list(gap.tau_range) if gap.tau_range else None}
    return out
