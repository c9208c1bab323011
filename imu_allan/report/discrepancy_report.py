"""
Reports of the discrepancy workflow: the JSON report, the console summary and the plots.

The plots (matplotlib, Agg): ``step<k>_<axis>.png`` per accepted step (measured curve with its
68 % band, the model band before and after), ``gap_per_step.png`` and ``overview.png``.
Findings (:mod:`imu_allan.core.discrepancy.findings`) are said in one sentence each
(:func:`finding_sentence`), the same in the JSON (``sentence``), the console and the page.
``--out DIR`` is written into a staging folder beside DIR and moved in when every file is
there (:func:`write_out_dir`).
"""

import math
import os
from pathlib import Path
import shutil
import tempfile

import numpy as np

from . import strict_json
from .strict_json import finite_or_none
from ..core.terms import TERMS
from ..core.units import conventional


def report_dict(result, source, findings=None):
    """
    Return the JSON report of one recording (contract fields plus source and method).

    ``findings``: a :class:`~imu_allan.core.discrepancy.FindingsResult` (with a model) adds
    ``findings``, ``consistent``, ``recordings`` and ``decision``; without one the steps are
    the findings (``missing_term``, a recalibration is no finding of a fitted start).
    """
    out = result.to_dict()
    out['source'] = source
    if findings is not None:
        out.update(findings.to_dict())
        out['notes'] = list(result.notes) + [n for n in findings.notes
                                             if n not in result.notes]
    else:
        out['findings'] = [_step_finding(step) for step in result.steps
                           if step.effect != 'recalibration']
        out['consistent'] = not out['findings']
    _add_sentences(out)
    return finite_or_none(out)


def _add_sentences(out):
    """Give every finding of a report, material or within the band, its ``sentence``."""
    for f in out['findings'] + out.get('within_band', []):
        f['sentence'] = finding_sentence(f)


def runs_report_dict(findings, model, sources):
    """Return the JSON report of several recordings: findings, recordings, the stated model."""
    out = {'sources': list(sources), 'model': model.to_dict()['axes']}
    out.update(findings.to_dict())
    _add_sentences(out)
    return finite_or_none(out)


def _step_finding(step):
    """Return a ``missing_term`` finding from a single-recording step (today's workflow)."""
    params = {k: v['value'] for k, v in step.parameters.items() if isinstance(v, dict)
              and 'value' in v}
    units = {k: v['unit'] for k, v in step.parameters.items() if isinstance(v, dict)
             and 'unit' in v}
    return {'class': 'missing_term', 'axis': step.axis, 'term': step.effect, 'factor': None,
            'factor_ci': None, 'factor_ci95': None, 'rate_exponent': None,
            'rate_exponent_ci': None, 'material': True,
            'evidence': {'parameters': params, 'units': units, 'gap_before': step.gap_before,
                         'gap_after': step.gap_after, 'p_value': step.p_value,
                         'tau_range_s': list(step.tau_range) if step.tau_range else None}}


def _num(x, digits=3):
    return '-' if x is None or not math.isfinite(x) else f'{x:.{digits}g}'


def _ci(ci, digits=3):
    return '' if not ci else f' [{_num(ci[0], digits)}, {_num(ci[1], digits)}]'


def _with_units(axis, term, value):
    """SI value with its unit and the conventional one beside it (continuous-time terms)."""
    unit = TERMS[term].param_unit(axis, TERMS[term].params[0])
    conv, conv_unit = conventional(axis, term, value)
    return f'{_num(value)} {unit} ({_num(conv)} {conv_unit})'


def _scaling(f):
    exp = f.get('rate_exponent')
    if exp is None:
        return ''
    ci = f.get('rate_exponent_ci')
    half = (ci[1] - ci[0]) / 2.0 if ci else None
    text = f', and scales with the sample rate as (f / 1 Hz)^{exp:.3f}' + \
        (f' +- {half:.3f}' if half else '') + ' (the factor is at 1 Hz)'
    if abs(exp + 0.5) < 0.1:
        text += ': a per-sample value read as a density'
    elif abs(exp - 0.5) < 0.1:
        text += ': a density read as a per-sample value'
    return text


def _suggestion(f):
    if f.get('parameter') is None:
        return ''
    ev = f.get('evidence', {})
    rate = ev.get('suggested_at_hz')
    key = f['parameter']
    if key.endswith('/stddev') and f.get('rate_exponent') is not None and \
            abs(f['rate_exponent'] + 0.5) < 0.1:
        return (f'; gz <stddev> is per sample: set it to N x sqrt({rate:g}) = '
                f'{f["suggested"]:#.2g} for the density you meant')
    if key.endswith('dynamic_bias_stddev'):
        return (f'; gz dynamic_bias_stddev drives the Gauss-Markov (its std is value x '
                f'sqrt(tau / 2)): set it to {f["suggested"]:.3g} for the std you meant')
    return f'; set {key} to {f["suggested"]:.3g}' + (f' (at {rate:g} Hz)' if rate else '')


def _what(f):
    """Return the words for what a finding's factor is about ('the white noise' ...)."""
    term = f.get('term') or ''
    if f['class'] == 'time_constant':
        return 'the Gauss-Markov correlation time'
    if f['class'] == 'metadata':
        return 'the covariance the messages state'
    if f['class'] == 'run_to_run':
        return f'the turn-on bias ({(f.get("evidence") or {}).get("kind")})'
    return 'the white noise' if term == 'white_noise' else 'the ' + term.replace('_', ' ')


def _within_sentence(f):
    """Say a significant factor inside the materiality band: consistent within X %."""
    return (f'{f["axis"]}: {_what(f)} is consistent with the stated (within '
            f'{_num(f.get("within_percent"), 2)} %): {_num(f.get("factor"), 4)}'
            f'{_ci(f.get("factor_ci95"), 4)} (95 %) x the stated{_scaling(f)}, inside the band '
            f'that matters.')


def _zeroed_sentence(f):
    """Say a term the model sets to zero that the data show, the density slot beside it."""
    ev = f.get('evidence') or {}
    words = (f.get('term') or '').replace('_', ' ')
    shown = ev.get('shown_as', '').replace('_', ' ')
    needed = ', '.join(f'{k} {_num(v)} {(ev.get("units_needed") or {}).get(k, "")}'.strip()
                       for k, v in (ev.get('needed') or {}).items())
    text = (f'{f["axis"]}: the model sets the {words} to zero, but the data show it (as a '
            f'{shown}; it needs {needed or "a value the data do not fix"})')
    density = ev.get('density')
    if density and density['factor'] < 1:
        text += (f', while the white-noise slot holds {_num(density["stated"])} '
                 f'{density["unit"]}, {_num(1.0 / density["factor"])} x the measured '
                 f'{_num(density["measured"])}: the per-sample RMS at '
                 f'{_num(density["per_sample_rms_at_hz"])} Hz (the record\'s RMS is '
                 f'{_num(density["record_rms"])}) in a density slot')
    elif density:
        text += (f'; the white noise is {_num(f.get("factor"))}{_ci(f.get("factor_ci"))} x '
                 f'the stated')
    if f.get('parameter') and f.get('suggested') is not None:
        text += f'; set {f["parameter"]} to {f["suggested"]:.3g}'
        also = ev.get('also') or ({density['parameter']: density['suggested']} if density
                                  and density['factor'] < 1 else {})
        text += ''.join(f', {k} to {v:.3g}' for k, v in also.items())
    return text + '.'


def finding_sentence(f):
    """One sentence for a finding (its report dict), with the corrected value when known."""
    cls, axis, term = f['class'], f['axis'], f.get('term')
    ev = f.get('evidence') or {}
    factor = f'{_num(f.get("factor"))}{_ci(f.get("factor_ci"))}'
    words = (term or '').replace('_', ' ')
    if f.get('material') is False:
        return _within_sentence(f)
    if cls == 'zeroed_term':
        return _zeroed_sentence(f)
    if cls in ('white_scale', 'bias_scale'):
        what = 'white noise' if term == 'white_noise' else words
        stated = ev.get('stated')
        measured = ev.get('measured', ev.get('measured_at_1hz'))
        values = ''
        if stated is not None and measured is not None and 'measured' in ev:
            values = (f' ({_with_units(axis, term, stated)} stated, '
                      f'{_with_units(axis, term, measured)} measured, continuous-time)')
        return (f'{axis}: the {what} is {factor} x the stated{values}{_scaling(f)}'
                f'{_suggestion(f)}.')
    if cls == 'time_constant':
        return (f'{axis}: the Gauss-Markov correlation time is {_num(ev.get("measured_s"))} s, '
                f'not the stated {_num(ev.get("stated_s"))} s (factor {factor}){_scaling(f)}.')
    if cls == 'term_absent':
        return (f'{axis}: the stated {words} has no effect in the data: at most '
                f'{_num((f.get("factor_ci") or [0, math.nan])[1])} x its stated size (68.3 %), '
                f'in {ev.get("recordings_without_it")} of {ev.get("recordings")} recordings; '
                f'the simulator does not apply it.')
    if cls == 'wrong_process':
        if ev.get('kind') == 'walk':
            return (f'{axis}: the bias keeps walking where the stated Gauss-Markov would level '
                    f'off: an unbounded random walk, driven at {factor} x the stated driving '
                    f'density.')
        tau_c = float(np.median(ev.get('tau_c_fitted_s') or [math.nan]))
        return (f'{axis}: the bias levels off (tau_c about {_num(tau_c)} s) where an unbounded '
                f'random walk is stated: a Gauss-Markov driven at {factor} x the stated K.')
    if cls == 'biased_drive':
        key = f' (of {f["parameter"]})' if f.get('parameter') else ''
        masked = ev.get('masked') or []
        return (f'{axis}: the bias drifts the same way in every run and axis '
                f'({ev.get("positive_runs")} of {ev.get("runs")} slopes positive here): its drive'
                f'{key} has a mean of {factor} x its stated per-step standard deviation (a '
                f'uniform draw in [0, 1) used for a zero-mean normal one gives 0.5); draw it '
                f'zero-mean, no value of the parameter corrects it'
                + (f' (what the drift also explains is left out: {", ".join(masked)})'
                   if masked else '') + '.')
    if cls == 'run_to_run':
        return _run_sentence(axis, ev, factor)
    if cls == 'metadata':
        return (f'{axis}: the messages state a covariance {factor} x the measured per-sample '
                f'variance{_scaling(f)}' +
                ('; a density squared where the per-sample variance N^2 f belongs'
                 if f.get('rate_exponent') is not None and abs(f['rate_exponent'] + 1) < 0.2
                 else '') + '.')
    if cls == 'missing_term':
        params = ', '.join(f'{k} {_num(v)} {ev.get("units", {}).get(k, "")}'.strip()
                           for k, v in (ev.get('parameters') or {}).items())
        return f'{axis}: the data show a {words} the model lacks ({params}).'
    return f'{axis}: {cls} {words} {factor}.'


def _run_sentence(axis, ev, factor):
    kind = ev.get('kind')
    stated = ev.get('stated') or {}
    if kind == 'decay':
        return (f'{axis}: the turn-on bias decays within a run (its last tenth is {factor} x '
                f'its first tenth) instead of staying constant.')
    if kind == 'bimodal':
        return (f'{axis}: the turn-on bias takes a random sign: {ev.get("opposite_sign_runs")} '
                f'of {ev.get("runs")} runs start opposite to the stated mean '
                f'{_num(stated.get("mean"))} (sign agreement {factor}, 1 as stated).')
    if kind == 'spread':
        return (f'{axis}: the turn-on bias varies between runs by '
                f'{_num(ev.get("observed_sigma"))} where {_num(stated.get("sigma"))} is stated '
                f'(factor {factor}).')
    return (f'{axis}: the turn-on bias averages {_num(ev.get("observed_mean"))} over the runs '
            f'where {_num(stated.get("mean"))} is stated (factor {factor}).')


def findings_text(report):
    """Console lines of the findings (one sentence each), the verdict, those within the band."""
    lines = (['findings: none: the data match the model'] if report.get('consistent') else
             ['findings:'] + [f'  - {f["sentence"]}' for f in report['findings']])
    within = report.get('within_band') or []
    if within:
        band = report.get('materiality', {}).get('scale')
        where = f' ({_num(band[0])}-{_num(band[1])})' if band else ''
        lines.append(f'within the band that matters{where}:')
        lines += [f'  - {f["sentence"]}' for f in within]
    return lines


def runs_summary_text(report):
    """Console summary of several recordings: each recording, then the findings."""
    lines = [f'{len(report["recordings"])} recordings against the stated model:']
    for r in report['recordings']:
        gaps = ', '.join(f'{a} {_num(g["gap_stated"], 3)}' for a, g in r['axes'].items())
        lines.append(f'  {r["source"]}: {r["n_samples"]} samples at {r["sample_rate_hz"]:.6g} '
                     f'Hz ({r["duration_s"] / 60.0:.1f} min); gap to the stated model: '
                     f'{gaps or "-"}')
    lines += findings_text(report)
    for note in report.get('notes', []):
        lines.append(f'note: {note}')
    return '\n'.join(lines)


def write_out_dir(out_dir, report, write_files):
    """
    Write ``report.json``, the other files (``write_files(staging)``) and ``report.html``.

    Everything goes into a staging folder beside ``out_dir`` first and is moved in when all
    of it is written, so a failed run leaves no half-written report.  Returns the file names.
    """
    out_dir = Path(out_dir)
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f'.{out_dir.name}.', dir=out_dir.parent))
    try:
        (staging / 'report.json').write_text(strict_json.dumps(report, indent=2), encoding='utf-8')
        write_files(staging)
        from .html import write_discrepancy_page  # last: it shows the files above
        write_discrepancy_page(staging, report)
        out_dir.mkdir(exist_ok=True)
        names = sorted(os.listdir(staging))
        for name in names:
            os.replace(staging / name, out_dir / name)
        return names
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _fmt_params(parameters, prefix=''):
    """``name=value [ci] unit`` for a step's parameters (nested per term for recalibration)."""
    parts = []
    for name, entry in parameters.items():
        if isinstance(entry, dict) and 'ci' in entry:
            lo, hi = entry['ci']
            parts.append(f'{prefix}{name}={entry["value"]:.4g} [{lo:.3g}, {hi:.3g}] '
                         f'{entry["unit"]}')
        elif isinstance(entry, dict):
            parts.append(_fmt_params(entry, f'{name}.'))
    return ', '.join(parts)


def summary_text(result, source):
    """Console summary: per axis the gap before/after and every step."""
    m = result.measured
    lines = [f'{source}: {m.n_samples} samples at {m.rate_hz:.6g} Hz '
             f'({m.n_samples / m.rate_hz / 60.0:.1f} min), start: {result.start}',
             'gap = sqrt(mean z^2) over averaging times (about 1 = consistent)']
    for axis in result.axes:
        g0, g1 = result.initial_gaps[axis], result.final_gaps[axis]
        verdict = 'consistent' if g1.consistent else 'INCONSISTENT'
        lines.append(f'  {axis:8s} gap {g0.value:7.2f} -> {g1.value:5.2f}  '
                     f'(threshold {g1.threshold:.2f}, {verdict})')
        for step in (s for s in result.steps if s.axis == axis):
            band = (f'{step.tau_range[0]:.3g}-{step.tau_range[1]:.3g} s'
                    if step.tau_range else 'n/a')
            lines.append(f'      + {step.effect:17s} tau {band:>16s}  gap {step.gap_before:.2f}'
                         f' -> {step.gap_after:.2f}  {_fmt_params(step.parameters)}')
        if not g1.consistent and g1.tau_range:
            lines.append(f'      unexplained between {g1.tau_range[0]:.3g} and '
                         f'{g1.tau_range[1]:.3g} s')
    for note in result.notes:
        lines.append(f'note: {note}')
    return '\n'.join(lines)


def single_summary_text(result, source, report):
    """Return the console summary of one recording followed by its findings."""
    return summary_text(result, source) + '\n' + '\n'.join(findings_text(report))


def write_plots(result, out_dir):
    """Per-step band plots, a gap-per-step chart and an overview; returns the file names."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    m = result.measured
    tau = m.tau
    files = []

    def draw_band(ax, band, color, label):
        lo, mid, hi = band.adev_band()
        ax.fill_between(tau, lo, hi, color=color, alpha=0.22, lw=0)
        ax.loglog(tau, mid, color=color, lw=1.6, label=label)
        if band.sims is not None:
            for run in band.sims:
                ax.loglog(tau, np.exp(run), color=color, lw=0.6, alpha=0.45)

    def draw_measured(ax, j):
        ax.fill_between(tau, m.ci_low[:, j], m.ci_high[:, j], color='0.2', alpha=0.15, lw=0)
        ax.loglog(tau, m.adev[:, j], 'o', color='black', ms=3.2, label='measured (68% CI)')

    unit = {True: 'rad/s', False: 'm/s²'}
    for k, step in enumerate(result.steps):
        j = list(m.axes).index(step.axis)
        before = result.snapshots[step.snapshot]
        after = result.snapshots[step.snapshot + 1]
        fig, (ax, axz) = plt.subplots(2, 1, figsize=(7.5, 6.8), sharex=True,
                                      gridspec_kw={'height_ratios': [3, 1.3]})
        draw_band(ax, before.bands[step.axis], 'tab:red',
                  f'before: {" + ".join(before.terms[step.axis])} (95% band)')
        draw_band(ax, after.bands[step.axis], 'tab:blue', f'after: + {step.effect} (95% band)')
        draw_measured(ax, j)
        if step.tau_range:
            for a in (ax, axz):
                a.axvspan(step.tau_range[0], step.tau_range[1], color='gold', alpha=0.18,
                          lw=0, label='where the effect shows' if a is ax else None)
        ax.plot([], [], color='0.4', lw=0.6, label='simulated runs (thin lines)')
        ax.set_ylabel(f'Allan deviation ({unit[step.axis.startswith("gyro")]})')
        ax.set_title(f'{step.axis}, step {step.index}: + {step.effect}   '
                     f'gap {step.gap_before:.2f} → {step.gap_after:.2f}', fontsize=11)
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8, loc='best')
        for snap, color in ((before, 'tab:red'), (after, 'tab:blue')):
            axz.semilogx(tau, snap.gaps[step.axis].z, '.-', color=color, lw=1, ms=4)
        axz.axhline(0, color='0.3', lw=0.8)
        for level in (-2, 2):
            axz.axhline(level, color='0.5', lw=0.8, ls='--')
        axz.set_ylabel('z (spreads)')
        axz.set_xlabel('averaging time τ (s)')
        axz.grid(True, which='both', alpha=0.3)
        fig.tight_layout()
        name = f'step{k + 1:02d}_{step.axis}_{step.effect}.png'
        fig.savefig(os.path.join(out_dir, name), dpi=110)
        plt.close(fig)
        files.append(name)

    # gap per step, one line per axis
    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for axis in result.axes:
        gaps = [result.initial_gaps[axis].value] + [s.gap_after for s in result.steps
                                                    if s.axis == axis]
        text = ' → '.join(f'+{e}' for e in result.effects(axis)) or 'nothing added'
        ax.plot(range(len(gaps)), gaps, 'o-', label=f'{axis}: {text}')
    thr = max(result.final_gaps[a].threshold for a in result.axes)
    ax.axhspan(0, thr, color='tab:green', alpha=0.10, lw=0)
    ax.axhline(thr, color='tab:green', ls='--', lw=1, label=f'consistent below ≈{thr:.2f}')
    ax.axhline(1.0, color='0.4', ls=':', lw=1)
    ax.set_yscale('log')
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter('%g'))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_yticks([0.5, 1, 2, 5, 10, 20, 50])
    top = max([result.initial_gaps[a].value for a in result.axes] + [thr]) * 1.3
    ax.set_ylim(min(0.3, 0.8 * min(result.final_gaps[a].value for a in result.axes)), top)
    ax.set_xlabel('step (effects added per axis)')
    ax.set_ylabel('gap (spreads, rms over τ)')
    n_max = max(1, max(len(result.effects(a)) for a in result.axes))
    ax.set_xticks(range(n_max + 1))
    ax.set_xlim(-0.3, n_max + 0.6)
    ax.set_title('Model-vs-data gap per step')
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7.5, loc='upper right')
    fig.tight_layout()
    fig.savefig(os.path.join(out_dir, 'gap_per_step.png'), dpi=110)
    plt.close(fig)
    files.append('gap_per_step.png')

    # overview: every axis, initial and final bands
    n = len(result.axes)
    cols = 3 if n > 2 else n
    rows = int(math.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False)
    first, last = result.snapshots[0], result.snapshots[-1]
    for i, axis in enumerate(result.axes):
        ax = axes[i // cols][i % cols]
        j = list(m.axes).index(axis)
        draw_band(ax, first.bands[axis], 'tab:red', 'initial model')
        if last is not first and last.terms[axis] != first.terms[axis]:
            draw_band(ax, last.bands[axis], 'tab:blue', 'final model')
        draw_measured(ax, j)
        g0, g1 = result.initial_gaps[axis].value, result.final_gaps[axis].value
        added = ', '.join(result.effects(axis)) or 'nothing added'
        ax.set_title(f'{axis}: gap {g0:.2f} → {g1:.2f}\n{added}', fontsize=9)
        ax.grid(True, which='both', alpha=0.3)
        ax.tick_params(labelsize=7)
        ax.set_xlabel('τ (s)', fontsize=8)
        ax.set_ylabel(f'ADEV ({unit[axis.startswith("gyro")]})', fontsize=8)
    for i in range(n, rows * cols):
        axes[i // cols][i % cols].axis('off')
    handles = [plt.Line2D([], [], color='tab:red', lw=1.6, label='initial model (95% band)'),
               plt.Line2D([], [], color='tab:blue', lw=1.6, label='final model (95% band)'),
               plt.Line2D([], [], color='black', marker='o', ls='', ms=4,
                          label='measured (68% CI)')]
    fig.legend(handles=handles, loc='lower center', ncol=3, fontsize=9, frameon=False)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(os.path.join(out_dir, 'overview.png'), dpi=100)
    plt.close(fig)
    files.append('overview.png')
    return files
