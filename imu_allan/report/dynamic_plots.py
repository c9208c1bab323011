"""
``analyze --dynamic``: the dynamic Allan deviation, its change test, report.json and the plots.

* ``dynamic`` in report.json: ``window_s``, ``step_s``, ``false_alarm_rate_per_day`` (the
  figure measured on simulated static data, per axis), ``target_false_alarms_per_day`` and
  ``changes`` (``axis``, ``t_s`` from the first analysed sample, ``what``, ``ratio``, ...).
* ``dynamic_gyro.png`` / ``dynamic_accel.png``: per axis, the deviation over window time x
  averaging time as a colour map, each value over the whole record's (median) deviation at
  that tau, so 1 (white) is "as usual"; detected changes marked (matplotlib, Agg).
"""

import math

import matplotlib

matplotlib.use('Agg')
from matplotlib.colors import LogNorm  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
import numpy as np  # noqa: E402

from ..core.change_detection import (  # noqa: E402
    ChangeTest,
    detect_changes,
    MEASURED_AXIS_DAYS,
    MEASURED_FALSE_ALARMS_PER_DAY,
)
from ..core.dynamic import dynamic_allan, normalized_adev  # noqa: E402
from ..core.units import is_gyro, sample_unit  # noqa: E402
from ..errors import InputError  # noqa: E402


def analyze_dynamic(analysis, window_s=None):
    """
    Return ``(DynamicResult, changes)`` of an analysis's samples; InputError if too short.

    Times (window centres, change times) count from the record's first sample, warm-up
    included (the warm-up itself is not analysed).
    """
    try:
        dyn = dynamic_allan(analysis.data, analysis.rate_hz, window_s or None,
                            axes=analysis.axes)
    except ValueError as exc:
        raise InputError(analysis.source, f'--dynamic: {exc}') from None
    changes = detect_changes(dyn)
    start = getattr(analysis, 'warmup_s', 0.0)  # times from the record's first sample
    dyn.t = dyn.t + start
    for c in changes:
        c.t_s += start
        c.detected_s += start
        c.extra['reported_s'] += start
    return dyn, changes


def dynamic_json(dyn, changes, warmup_s=0.0):
    """Return the report.json ``dynamic`` block (SI; times from the first sample)."""
    test = ChangeTest(dyn.rate_hz, int(round(dyn.step_s * dyn.rate_hz)), dyn.ms, dyn.k,
                      dyn.axes)
    return {'window_s': float(dyn.window_s), 'step_s': float(dyn.step_s),
            'false_alarm_rate_per_day': MEASURED_FALSE_ALARMS_PER_DAY,
            'false_alarm_note': 'measured per axis per day on simulated static data (thesis '
                                '3DM-GX3-25 model + rate random walk, 100 Hz, default window): '
                                f'0 alarms in {MEASURED_AXIS_DAYS:g} axis-days, 95 % upper '
                                f'bound {3.0 / MEASURED_AXIS_DAYS:.2g}; the threshold targets '
                                f'{test.target:g} per axis per day',
            'target_false_alarms_per_day': float(test.target),
            'tau_s': [float(t) for t in dyn.tau],
            'analysed_from_s': float(warmup_s),
            'changes': [c.to_json() for c in changes]}


def dynamic_sentence(dyn, changes):
    """Return the console line(s) of the change test."""
    head = (f'dynamic Allan deviation: window {dyn.window_s:.4g} s, step {dyn.step_s:.4g} s; '
            f'{len(changes)} change(s)')
    lines = [head]
    for c in changes:
        lines.append(f'  {c.axis:8} {c.what:17} at {c.t_s:.1f} s, ratio {c.ratio:.3g}')
    return '\n'.join(lines)


def plot_dynamic(path, dyn, changes, sensor):
    """Write ``dynamic_<sensor>.png``: one colour map per axis of that sensor."""
    cols = [j for j, a in enumerate(dyn.axes) if is_gyro(a) == (sensor == 'gyro')]
    fig = Figure(figsize=(9.0, 2.4 * max(len(cols), 1) + 0.8), dpi=100)
    if not cols or dyn.avar.shape[0] == 0:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(0.5, 0.5, f'no {sensor} axes', ha='center', va='center')
        fig.savefig(path)
        return
    norm_dev = normalized_adev(dyn)
    finite = norm_dev[:, :, cols][np.isfinite(norm_dev[:, :, cols])]
    span = max(float(np.max(np.abs(np.log10(finite)))) if finite.size else 0.1, 0.05)
    norm = LogNorm(10 ** -span, 10 ** span)
    hours = dyn.t[-1] > 3 * 3600
    scale, unit = (3600.0, 'h') if hours else (1.0, 's')
    t_edges = _edges(dyn.t / scale)
    tau_edges = np.sqrt(dyn.tau[:-1] * dyn.tau[1:]) if dyn.tau.size > 1 else dyn.tau
    tau_edges = np.concatenate(([dyn.tau[0] ** 2 / tau_edges[0]] if dyn.tau.size > 1 else
                                [dyn.tau[0] / 1.2], tau_edges,
                                [dyn.tau[-1] ** 2 / tau_edges[-1]] if dyn.tau.size > 1 else
                                [dyn.tau[0] * 1.2]))
    axes = fig.subplots(len(cols), 1, sharex=True, squeeze=False)[:, 0]
    mesh = None
    for ax, j in zip(axes, cols):
        axis = dyn.axes[j]
        mesh = ax.pcolormesh(t_edges, tau_edges, norm_dev[:, :, j].T, cmap='RdBu_r', norm=norm,
                             shading='flat')
        ax.set_yscale('log')
        ax.set_ylabel(f'{axis}\ntau (s)')
        for c in changes:
            if c.axis == axis and math.isfinite(c.t_s):
                ax.axvline(c.t_s / scale, color='k', lw=1.2, ls='--')
                ax.annotate(f'{c.what} x{c.ratio:.2g}', (c.t_s / scale, dyn.tau[-1]),
                            xytext=(3, -10), textcoords='offset points', fontsize=8,
                            bbox={'boxstyle': 'round', 'fc': 'w', 'alpha': 0.8})
    axes[-1].set_xlabel(f'window centre ({unit} from the first sample)')
    axes[0].set_title(f'dynamic Allan deviation ({sensor}, {sample_unit(dyn.axes[cols[0]])}) '
                      f'/ the record median at each tau\nwindow {dyn.window_s:.4g} s, step '
                      f'{dyn.step_s:.4g} s; dashed: detected changes', fontsize=9)
    fig.colorbar(mesh, ax=list(axes), label='deviation / record median', shrink=0.9)
    fig.savefig(path)


def _edges(centres):
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    mid = (centres[:-1] + centres[1:]) / 2.0
    return np.concatenate(([2 * centres[0] - mid[0]], mid, [2 * centres[-1] - mid[-1]]))


def write_dynamic_plots(folder, dyn, changes):
    """Write dynamic_gyro.png and dynamic_accel.png into ``folder``."""
    for sensor in ('gyro', 'accel'):
        plot_dynamic(f'{folder}/dynamic_{sensor}.png', dyn, changes, sensor)
