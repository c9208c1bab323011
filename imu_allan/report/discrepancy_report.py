"""
Reports of the discrepancy workflow: the JSON report, the console summary and the plots.

The plots (matplotlib, Agg): ``step<k>_<axis>.png`` per accepted step (measured curve with its
68 % band, the model band before and after), ``gap_per_step.png`` and ``overview.png``.
"""

import math
import os

import numpy as np


def _clean(value):
    """JSON-safe copy: NaN and inf become null, numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.bool_, bool)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def report_dict(result, source):
    """Return the JSON report (contract fields plus source and method)."""
    out = result.to_dict()
    out['source'] = source
    return _clean(out)


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
        gaps = [result.initial_gaps[axis].value]
        labels = []
        for step in (s for s in result.steps if s.axis == axis):
            gaps.append(step.gap_after)
            labels.append(step.effect)
        text = ' → '.join(f'+{e}' for e in labels) if labels else 'nothing added'
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
