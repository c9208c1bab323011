"""
``analyze --dynamic``: the plots of the dynamic Allan deviation and its change test.

Renders a :class:`~imu_allan.core.record.DynamicAnalysis` (computed with the record,
:func:`imu_allan.core.record.dynamic_analysis`); its report.json block and console lines are
in :mod:`.dynamic_report`.

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

from ..core.change.dynamic import normalized_adev  # noqa: E402
from ..core.units import is_gyro, sample_unit  # noqa: E402


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


def write_dynamic_plots(folder, part):
    """Write dynamic_gyro.png and dynamic_accel.png of a DynamicAnalysis into ``folder``."""
    for sensor in ('gyro', 'accel'):
        plot_dynamic(f'{folder}/dynamic_{sensor}.png', part.result, part.changes, sensor)
