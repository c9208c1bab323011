"""
Findings: where recordings of one configuration and the model it states disagree, by kind.

:func:`find_discrepancies` measures every recording against its stated model
(:mod:`.evidence`), pools each quantity over the recordings (:mod:`.pooling`: one factor, or a
factor at 1 Hz and a rate exponent), runs the tests that need several runs (:mod:`.runs`) and
compares message metadata with the measured per-sample variance.  Each disagreement becomes a
:class:`Finding` of one class:

=================  ==========================================================================
class              what the data show (``factor`` = measured / stated unless said)
=================  ==========================================================================
white_scale        the white noise (or quantization) is ``factor`` x the stated; with
                   ``rate_exponent`` it scales as (f / 1 Hz)^exponent and ``factor`` is at 1 Hz
bias_scale         a bias term's amplitude (Gauss-Markov sigma, K, B, R, sinusoid) likewise
time_constant      a Gauss-Markov tau_c
term_absent        a stated term has no effect in the data (factor 0, interval [0, upper])
wrong_process      a walk where a bounded Gauss-Markov is stated or the reverse; factor =
                   the measured driving density / the stated one
biased_drive       a drift of the same sign on every axis and run; factor = the drive's mean
                   per step / its stated standard deviation per step
zeroed_term        a term the model sets to zero (a simulator key at 0) that the data show;
                   factor = the white noise's measured / stated (< 1 when the density slot
                   carries the per-sample RMS that stood in for it); ``suggested`` the value
                   the zeroed term needs
run_to_run         the turn-on bias: spread, mean, a sign drawn at random (factor = sign
                   agreement), or a decay (factor = last-tenth / first-tenth level)
metadata           the messages' covariance / the measured per-sample variance
missing_term       an effect the model lacks (no factor: its fitted parameters are evidence)
=================  ==========================================================================

Every test of an analysis is counted and the decision level is Bonferroni over all of them at
``alpha`` (1 % by default): on recordings that match their model the whole list stays empty
in about 99 % of analyses.  A significant factor is a finding only when it matters
(:mod:`.materiality`: outside the band 0.8-1.25 by default); the others are kept aside as
*consistent within X %*.  Factors carry 68.3 % intervals (``factor_ci``) and 95 % ones
(``factor_ci95``).  SI units; ROS-free.
"""

from dataclasses import dataclass, field
import math

import numpy as np
from scipy.stats import chi2

from .band import ALPHA, Z95
from .evidence import amplitude, LogEstimate, measure_recording
from .materiality import Materiality
from .pooling import pool, z_critical
from .runs import drive_test, MIN_RUNS, turn_on_tests
from ..simulation.gauss_markov import best_gauss_markov, BIAS_TERMS, stationary_sigma
from ..terms import TERMS
from ..units import sensor_of

#: The order findings are listed in.
CLASSES = ('white_scale', 'bias_scale', 'time_constant', 'term_absent', 'wrong_process',
           'biased_drive', 'zeroed_term', 'run_to_run', 'metadata', 'missing_term')
#: Findings on an axis whose bias drifts with a biased drive that describe its bias terms: the
#: drift is in their Allan variance too, so they are left to the biased_drive finding.
DRIFT_MASKED = ('bias_scale', 'time_constant', 'wrong_process', 'term_absent', 'missing_term')
#: Terms whose amplitude is a white-type (short averaging time) level.
WHITE_TERMS = ('white_noise', 'quantization')
#: Tests per axis besides two per stated term (factor and its rate exponent): position,
#: process, four run-to-run tests, two for the metadata (factor and exponent), missing terms.
_TESTS_PER_AXIS = 9


@dataclass
class Finding:
    """One disagreement (see the module docstring); :meth:`to_dict` gives the report entry."""

    cls: str
    axis: str
    term: str
    factor: float = None
    factor_ci: list = None
    factor_ci95: list = None
    rate_exponent: float = None
    rate_exponent_ci: list = None
    evidence: dict = field(default_factory=dict)
    parameter: str = None
    suggested: float = None
    material: bool = True
    within_percent: float = None

    def to_dict(self):
        """Report entry: the contract keys, then ``parameter`` / ``suggested`` when known."""
        out = {'class': self.cls, 'axis': self.axis, 'term': self.term, 'factor': self.factor,
               'factor_ci': self.factor_ci, 'factor_ci95': self.factor_ci95,
               'rate_exponent': self.rate_exponent, 'rate_exponent_ci': self.rate_exponent_ci,
               'evidence': self.evidence, 'material': self.material}
        if not self.material:
            out['within_percent'] = self.within_percent
        if self.parameter is not None:
            out['parameter'] = self.parameter
            out['suggested'] = self.suggested
        return out


@dataclass
class FindingsResult:
    """Findings of one analysis with the per-recording summaries and the decision level."""

    findings: list
    recordings: list
    axes: list
    n_tests: int
    z_crit: float
    alpha: float
    notes: list = field(default_factory=list)
    evidence: dict = field(default_factory=dict)  # {axis: [AxisEvidence per recording]}
    within: list = field(default_factory=list)  # significant, inside the materiality band
    materiality: Materiality = field(default_factory=Materiality)

    @property
    def consistent(self):
        """Return True when the data match the model (no material finding)."""
        return not self.findings

    def to_dict(self):
        """Return ``findings``, ``consistent``, ``recordings`` and how the decisions were made."""
        return {'consistent': self.consistent,
                'findings': [f.to_dict() for f in self.findings],
                'within_band': [f.to_dict() for f in self.within],
                'materiality': self.materiality.to_dict(),
                'recordings': self.recordings,
                'decision': {'alpha': self.alpha, 'tests': self.n_tests,
                             'z_critical': self.z_crit,
                             'rule': 'Bonferroni over every test of the analysis; factor '
                                     'intervals 68.3 % (factor_ci) and 95 % (factor_ci95); a '
                                     'finding needs its factor outside the materiality band'},
                'notes': list(self.notes)}


def _scale_class(term):
    return 'white_scale' if term in WHITE_TERMS else 'bias_scale'


def _pooled_finding(cls, axis, term, pooled, evidence):
    """Make a :class:`Finding` from a :class:`.pooling.Pooled` factor."""
    evidence = dict(evidence)
    evidence['per_rate'] = [{'rate_hz': r['rate_hz'], 'factor': math.exp(r['log']),
                             'factor_ci': [math.exp(r['log'] - r['se']),
                                           math.exp(r['log'] + r['se'])],
                             'runs': r['runs']} for r in pooled.per_rate]
    if pooled.exponent is not None and not pooled.scaled:
        evidence['rate_exponent_measured'] = pooled.exponent
        evidence['rate_exponent_measured_ci'] = pooled.exponent_interval()
    return Finding(cls, axis, term, pooled.factor(), pooled.interval(), pooled.interval(Z95),
                   pooled.exponent if pooled.scaled else None,
                   pooled.exponent_interval() if pooled.scaled else None, evidence)


def _significant(pooled, z_crit):
    return pooled is not None and (pooled.z > z_crit or
                                   (pooled.scaled and pooled.z_exponent > z_crit))


def _axis_findings(axis, evs, z_crit, p_crit):
    """
    Return the findings of the Allan-variance evidence of one axis over its recordings.

    Also returns ``{term: Pooled}``, each stated term's pooled amplitude factor (significant
    or not).
    """
    out, scales = [], {}
    stated = evs[0].stated
    fitted = [e for e in evs if e.fitted]
    if not fitted:
        return out, scales
    unit = {t: TERMS[t].param_unit(axis, TERMS[t].params[0]) for t in stated}
    # a walk where a bounded bias is stated (or the reverse), in most of the recordings
    process = [e.process for e in fitted if e.process is not None]
    wrong = None
    if process and 2 * len(process) >= len(fitted):
        pooled = pool([p['estimate'] for p in process], z_crit)
        p_values = [p['p_value'] for p in process]
        if pooled is not None and fisher(p_values) < p_crit:
            wrong = process[0]['term']
            out.append(_pooled_finding('wrong_process', axis, wrong, pooled, {
                'kind': process[0]['kind'],
                'tau_c_fitted_s': [p['tau_c_fit'] for p in process],
                'stated': stated[wrong], 'p_values': p_values}))
    # a stated Gauss-Markov whose correlation time is off: the position tests of the
    # recordings combined (Fisher), the factor from the recordings that resolve the bend
    tau_pooled = None
    p_values = [e.position_p['gauss_markov'] for e in fitted if 'gauss_markov' in e.position_p]
    if 'gauss_markov' in stated and wrong is None and p_values and \
            fisher(p_values) < p_crit:
        tau_pooled = pool([e.positions['gauss_markov'] for e in fitted
                           if 'gauss_markov' in e.positions], z_crit)
        if tau_pooled is not None:
            out.append(_pooled_finding('time_constant', axis, 'gauss_markov', tau_pooled, {
                'stated_s': stated['gauss_markov']['tau_c'],
                'measured_s': stated['gauss_markov']['tau_c'] * tau_pooled.factor(),
                'unit': 's', 'p_value': fisher(p_values)}))
    for term, params in stated.items():
        if term == wrong:
            continue
        source = 'scales'
        if term == 'gauss_markov' and tau_pooled is not None:
            source = 'free_scales'  # with the correlation time refitted
        estimates = [getattr(e, source)[term] for e in fitted if term in getattr(e, source)]
        pooled = scales[term] = pool(estimates, z_crit)
        absent = [e.absent[term] for e in fitted if term in e.absent]
        # absent: most recordings do without it and reject its stated size, unless the
        # recordings that do show it tell how it scales with the rate
        if absent and 2 * len(absent) > len(fitted) and \
                fisher([a['p_stated'] for a in absent]) < p_crit and \
                not (_significant(pooled, z_crit) and pooled.scaled):
            # the tightest limits come from the recording that shows its absence best
            best = min(absent, key=lambda a: a['p_stated'])
            out.append(Finding('term_absent', axis, term, 0.0, [0.0, best['upper68']],
                               [0.0, best['upper_crit']],
                               evidence={'stated': params, 'unit': unit[term],
                                         'recordings_without_it': len(absent),
                                         'recordings': len(fitted)}))
            continue
        if _significant(pooled, z_crit):
            value = amplitude(params, term)
            out.append(_pooled_finding(_scale_class(term), axis, term, pooled, {
                'stated': value, 'unit': unit[term],
                'measured_at_1hz' if pooled.scaled else 'measured': value * pooled.factor()}))
    # effects the model lacks, in most of the recordings
    missing = {}
    for e in fitted:
        for m in e.missing:
            missing.setdefault(m['term'], []).append(m)
    for term, found in missing.items():
        if 2 * len(found) >= len(fitted):
            params = {k: float(np.median([m['params'][k] for m in found]))
                      for k in found[0]['params']}
            out.append(Finding('missing_term', axis, term, evidence={
                'parameters': params, 'units': {k: TERMS[term].param_unit(axis, k)
                                                for k in params},
                'per_recording': found, 'recordings_with_it': len(found),
                'recordings': len(fitted)}))
    return out, scales


def _zeroed_params(term, stated, found, params, tau_range, rate_hz):
    """
    Return the parameters ``term`` needs to be what the data show as ``found``, or None.

    The same family: its fitted parameters.  A zeroed Gauss-Markov (its stated tau_c kept
    when it has one) or random walk shown as another bias term: the Gauss-Markov closest to
    it over the measured averaging times
    (:func:`~imu_allan.core.simulation.gauss_markov.best_gauss_markov`), as sigma and tau_c or
    as its driving density.
    """
    if found == term:
        return dict(params)
    if term not in ('gauss_markov', 'rate_random_walk') or found not in BIAS_TERMS:
        return None
    gm = best_gauss_markov({found: params}, tau_range, rate_hz)
    if term == 'rate_random_walk':
        return {'value': gm.drive}
    tau_c = stated.get('tau_c') or 0.0
    if tau_c > 0 and found == 'rate_random_walk':  # below tau_c a Gauss-Markov is that walk
        return {'sigma': stationary_sigma(params['value'], tau_c), 'tau_c': tau_c}
    return {'sigma': gm.sigma, 'tau_c': gm.tau_c}


def _zeroed_findings(axis, evs, found, white):
    """
    Turn the missing effects that stand for a zeroed term into ``zeroed_term`` findings.

    ``found``: the axis's findings; ``white``: its pooled white-noise factor (or None).  A
    zeroed term is matched with the missing effect of its own family, else (a bias term) with
    the first missing bias effect.  The finding's factor is the white noise's: a density slot
    that carries a per-sample RMS (the bias folded into it) has factor 1 / sqrt(f) at the
    rate f of that RMS, which the evidence states with the record's own RMS beside it; the
    white-scale finding of the axis is folded into it.  Returns the new list.
    """
    zeroed = evs[0].zeroed
    missing = [f for f in found if f.cls == 'missing_term']
    if not zeroed or not missing:
        return found
    out = [f for f in found if f.cls != 'missing_term']
    fitted = [e for e in evs if e.fitted]
    tau_range = (min(e.tau_range[0] for e in fitted), max(e.tau_range[1] for e in fitted))
    rate = float(np.median([e.rate_hz for e in fitted]))
    for term, params in zeroed.items():
        match = next((m for m in missing if m.term == term), None) or next(
            (m for m in missing if term in BIAS_TERMS and m.term in BIAS_TERMS), None)
        if match is None:
            continue
        missing.remove(match)
        density = next((f for f in out if f.cls == 'white_scale' and f.term == 'white_noise'),
                       None)
        if density is not None:
            out.remove(density)
        needed = _zeroed_params(term, params, match.term, match.evidence['parameters'],
                                tau_range, rate)
        evidence = {'shown_as': match.term, **match.evidence, 'stated': dict(params),
                    'needed': needed, 'density': _density_evidence(evs, white),
                    'units_needed': {k: TERMS[term].param_unit(axis, k) for k in needed or {}}}
        key = TERMS[term].params[0]
        f = Finding('zeroed_term', axis, term, evidence=evidence, parameter=f'{axis}.{term}.{key}',
                    suggested=needed[key] if needed else None)
        if white is not None:
            f.factor, f.factor_ci, f.factor_ci95 = white.factor(), white.interval(), \
                white.interval(Z95)
            if white.scaled:
                f.rate_exponent, f.rate_exponent_ci = white.exponent, white.exponent_interval()
        out.append(f)
    return out + missing


def _density_evidence(evs, white):
    """Return what the white-noise slot holds against the data (and the record's RMS)."""
    stated = evs[0].stated.get('white_noise')
    if stated is None or white is None:
        return None
    n_stated = amplitude(stated, 'white_noise')
    rms = float(np.median([e.rms for e in evs]))
    factor = white.factor()
    return {'stated': n_stated, 'measured': n_stated * factor, 'factor': factor,
            'unit': TERMS['white_noise'].param_unit(evs[0].axis, 'value'),
            'parameter': f'{evs[0].axis}.white_noise.value', 'suggested': n_stated * factor,
            'record_rms': rms, 'stated_over_record_rms': n_stated / rms if rms > 0 else None,
            'per_sample_rms_at_hz': factor ** -2 if factor < 1 else None}


def _run_findings(axis, evs, stated, p_crit):
    """run_to_run findings of one axis: decay and sign first, spread and mean otherwise."""
    tests = {t['kind']: t for t in turn_on_tests(axis, evs, stated)}
    out = []
    hit = {k for k, t in tests.items() if t['p_value'] < p_crit}
    kinds = [k for k in ('decay', 'bimodal') if k in hit]
    if not kinds:  # spread and mean describe the start level only when it stays and is one
        kinds = [k for k in ('spread', 'mean') if k in hit]
    for kind in kinds:
        t = tests[kind]
        ev = dict(t['evidence'])
        ev.update({'kind': kind, 'p_value': t['p_value'], 'stated': dict(stated),
                   'runs': len(evs)})
        out.append(Finding('run_to_run', axis, 'turn_on_bias', t['factor'], t['factor_ci'],
                           t['factor_ci95'], evidence=ev))
    return out, 'decay' in hit


def _metadata_finding(axis, evs, z_crit):
    """Covariance stated in the messages against the measured per-sample white variance."""
    estimates = []
    for e in evs:
        if e.stated_variance is None or not e.stated_variance > 0:
            continue
        var, edf = e.white_variance
        if not (var > 0 and edf > 0):
            continue
        estimates.append(LogEstimate(math.log(e.stated_variance / var), math.sqrt(2.0 / edf),
                                     e.rate_hz))
    pooled = pool(estimates, z_crit)
    if not _significant(pooled, z_crit):
        return None
    return _pooled_finding('metadata', axis, 'white_noise', pooled, {
        'stated_variance': [e.stated_variance for e in evs if e.stated_variance],
        'measured_variance': [e.white_variance[0] for e in evs if e.stated_variance],
        'rates_hz': [e.rate_hz for e in evs if e.stated_variance],
        'unit': 'rad^2/s^2' if axis.startswith('gyro') else 'm^2/s^4',
        'measured_as': 'Allan variance at the shortest averaging time (per-sample white '
                       'variance)'})


def count_tests(models, recordings):
    """Count the tests an analysis makes (the Bonferroni family) from the stated models."""
    axes = set()
    terms = 0
    for model, rec in zip(models, recordings):
        for axis in rec.axes:
            if axis in axes or not (model.terms.get(axis) or axis in model.turn_on_bias):
                continue
            axes.add(axis)
            terms += len(model.terms.get(axis, {}))
    return _TESTS_PER_AXIS * len(axes) + 2 * terms + 2


def _measure_all(recordings, models, z_crit, alpha, points_per_decade, min_clusters):
    """Return each axis's evidence over the recordings and one summary per recording."""
    per_axis = {}
    summaries = []
    for rec, m in zip(recordings, models):
        evidence = measure_recording(rec, m, z_crit, alpha, points_per_decade, min_clusters)
        summaries.append({'source': rec.source, 'sample_rate_hz': float(rec.rate_hz),
                          'n_samples': int(rec.data.shape[0]),
                          'duration_s': float(rec.duration_s),
                          'axes': {a: {'gap_stated': e.gap_stated, 'gap_fitted': e.gap_fitted,
                                       'consistent_fitted': e.consistent_fitted}
                                   for a, e in evidence.items() if e.fitted}})
        for axis, ev in evidence.items():
            per_axis.setdefault(axis, []).append(ev)
    return per_axis, summaries


def _per_axis_findings(per_axis, turn_on_bias, z_crit, p_crit):
    """
    Return the findings each axis shows on its own and what the drive test needs.

    Returns ``(findings, decaying, few_runs)``: ``decaying`` the axes whose turn-on bias
    decays (left out of the drive test), ``few_runs`` those with a stated turn-on bias but
    fewer than :data:`.runs.MIN_RUNS` recordings.
    """
    findings = []
    decaying = set()
    few_runs = []
    for axis, evs in per_axis.items():
        axis_found, scales = _axis_findings(axis, evs, z_crit, p_crit)
        findings += _zeroed_findings(axis, evs, axis_found, scales.get('white_noise'))
        turn_on = turn_on_bias.get(axis)
        if turn_on is not None:
            runs, decays = _run_findings(axis, evs, turn_on, p_crit)
            findings += runs
            if decays:
                decaying.add(axis)
            if len(evs) < MIN_RUNS:
                few_runs.append(axis)
        meta = _metadata_finding(axis, evs, z_crit)
        if meta is not None:
            findings.append(meta)
    return findings, decaying, few_runs


def _with_drive_findings(findings, per_axis, decaying, p_crit):
    """Return ``findings`` with each sensor's biased_drive findings (:func:`_drive_findings`)."""
    stated_terms = {axis: evs[0].stated for axis, evs in per_axis.items()}
    for sensor in ('gyro', 'accel'):
        group = {a: evs for a, evs in per_axis.items()
                 if sensor_of(a) == sensor and a not in decaying}
        p, axes = drive_test(group, stated_terms)
        if p < p_crit:
            findings = _drive_findings(findings, axes, stated_terms, p)
    return findings


def find_discrepancies(recordings, model, alpha=ALPHA, points_per_decade=10,
                       min_clusters=10, materiality=None):
    """
    Compare recordings of one configuration with the noise model it states; FindingsResult.

    ``recordings``: :class:`.evidence.Recording` s at any rates, any number of runs;
    ``model``: the stated model (SI, continuous time), or one per recording when it depends on
    the rate (a per-sample quantity stated by a simulator file).  ``alpha`` is the family-wise
    level (Bonferroni over :func:`count_tests`); ``points_per_decade`` and ``min_clusters`` the
    estimator's averaging-time grid; ``materiality`` the band of factors that do not matter
    (default 0.8-1.25, :mod:`.materiality`): a significant factor inside it goes to ``within``.
    """
    models = list(model) if isinstance(model, (list, tuple)) else [model] * len(recordings)
    if len(models) != len(recordings):
        raise ValueError('one model per recording (or one for all)')
    n_tests = count_tests(models, recordings)
    z_crit = z_critical(alpha, n_tests)
    p_crit = alpha / n_tests
    notes = []
    per_axis, summaries = _measure_all(recordings, models, z_crit, alpha, points_per_decade,
                                       min_clusters)
    skipped = sorted({a for r in recordings for a in r.axes} - set(per_axis))
    if skipped:
        notes.append(f'the model states nothing for {", ".join(skipped)}: not compared')
    findings, decaying, few_runs = _per_axis_findings(per_axis, models[0].turn_on_bias,
                                                      z_crit, p_crit)
    if few_runs:
        notes.append(f'turn-on bias of {", ".join(few_runs)}: compared across runs from '
                     f'{MIN_RUNS} recordings on ({len(recordings)} given)')
    findings = _with_drive_findings(findings, per_axis, decaying, p_crit)
    findings.sort(key=lambda f: (CLASSES.index(f.cls), f.axis))
    materiality = materiality or Materiality()
    for f in findings:
        f.material = materiality.material(f)
        if not f.material:
            f.within_percent = materiality.within_percent(f)
    return FindingsResult([f for f in findings if f.material], summaries, sorted(per_axis),
                          n_tests, z_crit, alpha, notes, per_axis,
                          [f for f in findings if not f.material], materiality)


def _drive_findings(findings, axes, stated_terms, p):
    """
    Add the biased_drive findings of one sensor's drifting axes; mask what the drift explains.

    On those axes the findings about the bias terms (:data:`DRIFT_MASKED`, not white noise)
    describe the drift as well (a ramp, a bias scale or correlation time fitted to it): they
    are left out and named in the drive's evidence (``masked``).
    """
    out = []
    masked = {}
    for f in findings:
        if f.axis in axes and f.cls in DRIFT_MASKED and f.term not in WHITE_TERMS:
            masked.setdefault(f.axis, []).append(f'{f.cls} {f.term}')
        else:
            out.append(f)
    for axis, d in axes.items():
        term = next((t for t in ('rate_random_walk', 'gauss_markov')
                     if t in stated_terms.get(axis, {})), None)
        out.append(Finding('biased_drive', axis, term, d['factor'], d['factor_ci'],
                           d['factor_ci95'], evidence={**d['evidence'], 'p_value': p,
                                                       'masked': masked.get(axis, [])},
                           parameter=f'{axis}.{term}' if term else None))
    return out


def fisher(p_values):
    """Fisher's combination of independent p-values: -2 sum ln p ~ chi-square(2k)."""
    stat = -2.0 * float(np.sum(np.log(np.maximum(p_values, 1e-300))))
    return float(chi2.sf(stat, 2 * len(p_values)))
