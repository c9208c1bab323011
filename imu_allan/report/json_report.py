"""
report.json and the console text of a record's analysis, each assembled here in one place.

:func:`record_to_json` and :func:`record_text` render a
:class:`~imu_allan.core.record.RecordAnalysis`: the estimate (:func:`analysis_to_json`,
:func:`console_summary`), then one block per part computed, in the order of :data:`BLOCKS`
and :data:`LINES`.  JSON follows the contract in docs/interfaces.md (SI units,
continuous-time coefficients) and adds ``verdict``, ``timing``, ``outliers`` and ``kalibr``
blocks.
"""

from dataclasses import dataclass
import math

import numpy as np

from .advice import advice_sentence, advice_to_json
from .dynamic_report import dynamic_json, dynamic_sentence
from .fit_quality import (
    adequacy_lines,
    fit_json,
    line_sentence,
    sensor_json,
    sensor_sentence,
    span_line,
)
from .kalibr import kalibr_values
from .temperature_report import temperature_json, temperature_sentence
from ..core.checks.warmup import warmup_sentence
from ..core.export_values import motion_withheld
from ..core.terms import TERMS
from ..core.units import sample_unit

ESTIMATOR = ('fully overlapping Allan deviation (NIST SP1065 eq. 11); 68.3 % chi-square '
             'intervals with Greenhall-Riley EDF; joint GLS non-negative fit')


def _floats(values):
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _curve(res, j, key, dev):
    """One axis (column ``j``) of a deviation: ``tau``, ``key`` (``dev``), interval, EDF."""
    return {'tau': _floats(res.tau), key: _floats(dev[:, j]), 'ci_low': _floats(res.ci_low[:, j]),
            'ci_high': _floats(res.ci_high[:, j]), 'edf': _floats(res.edf[:, j])}


def analysis_to_json(analysis, samples=None):
    """
    Return the report dictionary of one analysis (JSON-ready).

    ``upper_limits``: ``{axis: {term: 95 % upper limit}}`` of undetected N and K (SI).  With
    the :class:`~imu_allan.formats.samples.Samples` analysed, also ``recording``: the Imu
    ``topic`` and ``frame_id`` (bags; '' otherwise) and ``start_s``, the first stamp (s).
    """
    res = analysis.result
    axes = {}
    for j, axis in enumerate(analysis.axes):
        axes[axis] = {
            'unit': sample_unit(axis),
            'adev': _curve(res, j, 'adev', res.adev),
            'terms': analysis.fit.term_report(axis),
            'limits': analysis.fit.limit_report(axis),
            'fit': {'chi2': float(analysis.fit.chi2[axis]), 'dof': int(analysis.fit.dof[axis]),
                    'selected': list(analysis.fit.fits[axis].terms),
                    # the fitted curve at adev.tau (the selected set and the lines): what the
                    # plots draw, unresolved terms included (their values are limits only)
                    'model_adev': _floats(np.sqrt(analysis.fit.model_avar(axis, res.tau))),
                    'alternatives': analysis.fit.alternatives(axis),
                    'rejected': analysis.fit.rejected(axis),
                    'decided_by': analysis.fit.decided_by(axis),
                    **fit_json(analysis.fit, axis)},
        }
        if analysis.deviations:
            axes[axis]['deviations'] = {kind: _curve(d, d.axis_index(axis), 'dev', d.dev)
                                        for kind, d in analysis.deviations.items()}
    timing = analysis.timing
    kalibr, _ = kalibr_values(analysis)
    report = {
        'source': analysis.source,
        'n_samples': int(analysis.n_samples),
        'sample_rate_hz': float(analysis.rate_hz),
        'duration_s': float(analysis.duration_s),
        'units': 'SI; noise coefficients are continuous-time',
        'estimator': ESTIMATOR,
        'axes': axes,
        'verdict': {
            'static': bool(analysis.static),
            'motion': analysis.motion,
            'tau_max_s': float(res.tau[-1]),
            'warmup_s': float(analysis.warmup_s),
            'warnings': list(analysis.warnings),
        },
        'timing': {'gaps': timing.n_gaps, 'missing_samples': timing.missing_samples,
                   'longest_gap_s': timing.longest_gap_s, 'jitter': timing.jitter},
        'outliers': {'rule': 'Tukey F=3', 'replaced': analysis.outliers.replaced,
                     'counts': dict(analysis.outliers.counts)},
        'kalibr': kalibr,
        'integrity': analysis.integrity,
        'upper_limits': analysis.upper_limits,
    }
    if samples is not None:
        report['recording'] = {'topic': samples.topic, 'frame_id': samples.frame_id,
                               'start_s': float(samples.t[0])}
    return report


def _fmt(value):
    return f'{value:.4g}' if value is not None and math.isfinite(value) else '-'


def console_summary(analysis):
    """Return a human-readable summary: terms in SI and conventional units, then the verdict."""
    lines = [f'{analysis.source}: {analysis.n_samples} samples at {analysis.rate_hz:.6g} Hz, '
             f'{analysis.duration_s:.1f} s ({analysis.duration_s / 3600:.2f} h); averaging times '
             f'{analysis.result.tau[0]:.3g} .. {analysis.result.tau[-1]:.4g} s',
             'noise coefficients (continuous-time, 68.3 % intervals):',
             f'  {"axis":8} {"term":17} {"value (SI)":>11} {"interval (SI)":>23} {"unit":>17}'
             f'  {"conventional":>11} {"unit"}']
    moved = motion_withheld(analysis)
    if moved:
        lines[1] = ('the IMU MOVED: these curves measure the motion, not the sensor noise; '
                    'the fit of the motion (no intervals: they assume noise):')
    for axis in analysis.axes:
        report = analysis.fit.term_report(axis)
        if not report:
            lines.append(f'  {axis:8} (no term resolved)')
        for term, entry in report.items():
            lo, hi = entry['ci']
            conv = entry['conventional']
            interval = f'{"(motion)":>24}' if moved else f'[{_fmt(lo):>10}, {_fmt(hi):>10}]'
            lines.append(f'  {axis:8} {term:17} {_fmt(entry["value"]):>11} '
                         f'{interval} {entry["unit"]:>17}'
                         f'  {_fmt(conv["value"]):>11} {conv["unit"]}')
            extra = TERMS[term].position   # a hump term's tau_c or frequency_hz
            if extra in entry:
                e = entry[extra]
                lines.append(f'  {"":8} {"  " + extra:17} {_fmt(e["value"]):>11} '
                             f'[{_fmt(e["ci"][0]):>10}, {_fmt(e["ci"][1]):>10}] '
                             f'{e["unit"]:>17}')
        for term, entry in analysis.fit.limit_report(axis).items():
            if entry['upper_limit'] is None or moved:
                continue
            conv = entry['conventional']
            lines.append(f'  {axis:8} {term:17} {"< " + _fmt(entry["upper_limit"]):>11} '
                         f'{"(95 % upper limit)":>24} {entry["unit"]:>17}'
                         f'  {"< " + _fmt(conv["upper_limit"]):>11} {conv["unit"]}')
    lines += [line for line in (span_line(analysis.fit), line_sentence(analysis.fit)) if line]
    lines += adequacy_lines(analysis.fit)
    kalibr, per_axis = kalibr_values(analysis)
    kal = ', '.join(f'{k} {_fmt(v)}' + (' (upper limit)' if k in kalibr['upper_limits'] else '')
                    + (' (model inadequate)' if k in kalibr['inadequate'] else '')
                    for k, v in kalibr.items() if k not in ('update_rate', 'upper_limits',
                                                            'inadequate'))
    if moved:
        kal = 'not given: the IMU moved (analyze --allow-motion gives the numbers anyway)'
    lines.append(f'Kalibr (continuous-time, worst axis): {kal}')
    lines.append('verdict: ' + ('static' if analysis.static else 'NOT static (moving)'))
    if analysis.warmup_s:
        lines.append(warmup_sentence(analysis.warmup_s))
    if analysis.outliers.total:
        lines.append(f'outliers beyond Tukey fences (F=3): {analysis.outliers.total}')
    for warning in analysis.warnings:
        lines.append(f'warning: {warning}')
    if analysis.integrity:
        lines.append(f'integrity: {analysis.integrity}')
    return '\n'.join(lines)


def denoised_json(part):
    """Return the ``denoised`` block: per axis the denoised record's terms and its ADEV."""
    den = part.analysis
    return {a: {'terms': den.fit.term_report(a),
                'adev': {'tau': den.result.tau.tolist(), 'adev': den.result.adev[:, j].tolist()}}
            for j, a in enumerate(den.axes)}


#: report.json blocks of a record's parts, in report order: (key, RecordAnalysis field,
#: renderer); a part that is None (not asked, or absent) has no block.
BLOCKS = (('sensor', 'sensor', sensor_json),
          ('advice', 'advice', advice_to_json),
          ('denoised', 'denoised', denoised_json),
          ('dynamic', 'dynamic', dynamic_json),
          ('temperature', 'temperature', temperature_json))

#: Console lines of a record's parts after the summary, in order: (field, renderer).
LINES = (('sensor', sensor_sentence),
         ('advice', lambda advice: advice_sentence(advice_to_json(advice))),
         ('temperature', temperature_sentence),
         ('dynamic', dynamic_sentence))


@dataclass
class OutFiles:
    """What ``--out DIR`` holds, for report.json (``outputs.write_out_dir`` returns it)."""

    #: the denoised bag folder (``DIR/denoised_bag``), None without one
    denoised_bag: str = None
    #: the names written into DIR; None while report.json itself is being written
    files: list = None


def record_to_json(record, out=None):
    """
    Return the report dictionary of a record's analysis (JSON-ready), the one place it is made.

    The estimate's blocks (:func:`analysis_to_json`, with ``recording``), the parts'
    (:data:`BLOCKS`), ``overbound`` (the exports' block, computed with the record) and, with
    ``out`` (:class:`OutFiles`), ``denoised_bag`` before it and ``out_files`` after it.
    """
    report = analysis_to_json(record.analysis, record.samples)
    for key, name, render in BLOCKS:
        part = getattr(record, name)
        if part is not None:
            report[key] = render(part)
    if out is not None and out.denoised_bag is not None:
        report['denoised_bag'] = out.denoised_bag
    if record.overbound is not None and record.overbound.block is not None:
        report['overbound'] = record.overbound.block
    if out is not None and out.files is not None:
        report['out_files'] = list(out.files)
    return report


def record_text(record):
    """Return the console text of a record's analysis: the summary, then each part's lines."""
    lines = [console_summary(record.analysis)]
    for name, render in LINES:
        part = getattr(record, name)
        if part is not None:
            lines.append(render(part))
    return '\n'.join(lines)
