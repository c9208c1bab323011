"""
PNG plots of an analysis (matplotlib, Agg backend, no screen needed).

* ``adev_<sensor>.png``: Allan deviation per axis with its 68.3 % band, each fitted term's line
  (dashed), the total model (solid), slope guides -1, -1/2, 0, +1/2, +1 (grey), and the
  denoised curve when given.
* ``timeseries.png``: the raw samples per axis (1-s means on top) with Tukey outliers marked.
* :class:`LiveFigure`: the allan node's ``imu/allan_plot/compressed`` image, both sensors' panels
  drawn by the same :func:`draw_adev`.
"""

from fractions import Fraction
import io
import math

import matplotlib

matplotlib.use('Agg')
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
import matplotlib.patches  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..core import terms as _terms  # noqa: E402
from ..core.units import GYRO_AXES, IEEE_TERMS, is_gyro, sample_unit  # noqa: E402

#: Colour of each axis (x, y, z) in every plot.
AXIS_COLORS = {'x': 'tab:red', 'y': 'tab:green', 'z': 'tab:blue'}
#: The slope guides: the IEEE terms' ADEV slopes (-1 .. +1).
_SLOPES = tuple(float(Fraction(_terms.TERMS[t].adev_slope)) for t in IEEE_TERMS)


def _slope_guides(ax, tau, adev, curves=()):
    """
    Draw a fan of the IEEE slopes (-1 .. +1, 0.7 decade long) clear of every curve.

    The fan goes below the curves at the left or the right end, or above them at the right,
    whichever stretches the plot's range least; ``curves`` are ``(tau, y)`` of the other lines
    drawn (fitted terms, model), so that the fan and its labels cross none of them.
    """
    span = min(10.0 ** 0.7, tau[-1] / (tau[0] * 1.3))
    spans = [(tau, col) for col in np.atleast_2d(np.asarray(adev).T)] + list(curves)
    y_all = np.concatenate([np.ravel(y) for _, y in spans])
    y_all = y_all[np.isfinite(y_all) & (y_all > 0)]
    y_min, y_max = y_all.min(), y_all.max()
    best = None
    for t0, below in ((tau[0] * 1.3, True), (tau[-1] / (1.3 * span), True),
                      (tau[-1] / (1.3 * span), False)):
        inside = np.concatenate([np.ravel(y)[(np.ravel(t) >= t0) & (np.ravel(t) <= t0 * span)]
                                 for t, y in spans])
        inside = inside[np.isfinite(inside) & (inside > 0)]
        if not inside.size:
            continue
        # the fan spans a factor `span` up and down from y0; 1.8x clearance for its labels
        y0 = inside.min() / (span * 1.8) if below else inside.max() * span * 1.8
        stretch = max(0.0, math.log10(y_min / (y0 / span))) + \
            max(0.0, math.log10(y0 * span / y_max))
        if best is None or stretch < best[0]:
            best = (stretch, t0, y0)
    if best is None:
        return
    _, t0, y0 = best
    ts = np.array([t0, t0 * span])
    for slope in _SLOPES:
        ys = y0 * (ts / t0) ** slope
        ax.plot(ts, ys, color='0.65', lw=0.8, zorder=0)
        ax.annotate(f'{slope:+g}' if slope else '0', (ts[1], ys[1]), fontsize=7,
                    color='0.45', xytext=(2, 0), textcoords='offset points', va='center')
    ax.annotate('slopes', (t0, y0), fontsize=7, color='0.45', xytext=(0, -9),
                textcoords='offset points')


def _label_index(curve, total):
    """
    Index where to name a fitted term: where its line runs furthest below the model.

    There the measured points (which follow the model) are far above the label, so the two
    never collide; only points within 1.2 decades of the model count (the rest is off the
    plot's interesting range).
    """
    ratio = curve / total
    visible = np.flatnonzero(ratio >= 10.0 ** -1.2)
    if not visible.size:
        return int(np.nanargmax(ratio))
    return int(visible[np.nanargmin(ratio[visible])])


def _grouped_legend(ax, axes, below):
    """One legend column per axis (its measured points, model, extra curves), in axis order."""
    handles, labels = ax.get_legend_handles_labels()
    groups = {a: [(h, lab) for h, lab in zip(handles, labels) if lab.split()[0] == a]
              for a in axes}
    rows = max((len(g) for g in groups.values()), default=0)
    if not rows:
        return
    blank = matplotlib.patches.Rectangle((0, 0), 0, 0, visible=False)
    entries = [e for a in axes for e in groups[a] + [(blank, '')] * (rows - len(groups[a]))]
    kwargs = {'loc': 'upper center', 'bbox_to_anchor': (0.5, -0.12), 'frameon': False} \
        if below else {'loc': 'best'}
    ax.legend(*zip(*entries), ncol=len(axes), fontsize=8, **kwargs)


def draw_adev(ax, result, fitted, axes, denoised=None, legend_below=False, deviations=None):
    """
    Draw one sensor's Allan deviation panel (module docstring) on a matplotlib ``Axes``.

    ``fitted``: a :class:`~imu_allan.core.fit.FittedModel`, or None before the first fit; each
    term is named once, below its line where it runs furthest under the model, clear of the
    points.  ``denoised`` (an :class:`AllanResult`) is dotted, the extra ``deviations`` (kind
    -> DeviationResult) open markers; one legend column per axis, under the plot with
    ``legend_below``.  The one drawing of ``analyze``'s plots (PNG and the page's SVG) and the
    allan node's live figure.
    """
    tau = result.tau
    fine = np.logspace(math.log10(tau[0]), math.log10(tau[-1]), 200)
    named = False
    lines = []  # (tau, y) of the fitted lines, kept clear of the slope fan
    for axis in axes:
        j = result.axis_index(axis)
        color = AXIS_COLORS[axis[-1]]
        ax.fill_between(tau, result.ci_low[:, j], result.ci_high[:, j], color=color,
                        alpha=0.18, lw=0)
        ax.plot(tau, result.adev[:, j], 'o', ms=2.5, color=color, label=f'{axis} measured')
        if fitted is not None and axis in fitted.fits:
            total = np.sqrt(fitted.model_avar(axis, fine))
            for term, params in fitted.model.terms.get(axis, {}).items():
                curve = np.sqrt(_terms.term_avar(term, params, fine, result.rate_hz))
                ax.plot(fine, curve, '--', color=color, lw=0.8, alpha=0.7)
                lines.append((fine, curve))
                if not named:  # name each term once, below its line, away from the points
                    k = _label_index(curve, total)
                    ax.annotate(term.replace('_', ' '), (fine[k], curve[k]), fontsize=8,
                                color='0.25', xytext=(0, -3), textcoords='offset points',
                                va='top', ha='right' if k > fine.size // 2 else 'left',
                                bbox={'boxstyle': 'round,pad=0.1', 'fc': 'white', 'ec': 'none',
                                      'alpha': 0.75})
            named = True
            ax.plot(fine, total, '-', color=color, lw=1.2, label=f'{axis} model')
            lines.append((fine, total))
            span = fitted.tau_range(axis)
            if span is not None and span.lo > tau[0] * 1.001:  # what the fit left out
                ax.axvspan(tau[0], span.lo, color=color, alpha=0.07, lw=0)
        if denoised is not None:
            dj = denoised.axis_index(axis)
            ax.plot(denoised.tau, denoised.adev[:, dj], ':', color=color, lw=1.4,
                    label=f'{axis} denoised')
    draw_deviations(ax, deviations, axes)
    columns = [result.axis_index(a) for a in axes]
    _slope_guides(ax, tau, result.adev[:, columns], lines)
    ax.set_xscale('log')
    ax.set_yscale('log')
    # the measured curves set the scale: a term far below them (a line's nulls, a walk at
    # the shortest tau) runs off the bottom instead of squeezing the data
    low, high = np.nanmin(result.ci_low[:, columns]), np.nanmax(result.ci_high[:, columns])
    if np.isfinite(low) and np.isfinite(high) and 0.0 < low < high:
        ax.set_ylim(low / 4.0, high * 3.0)
    ax.set_xlabel('averaging time tau (s)')
    ax.set_ylabel(f'Allan deviation ({sample_unit(axes[0])})')
    ax.grid(True, which='both', color='0.92', lw=0.5)
    _grouped_legend(ax, axes, legend_below)


#: Line style of each extra deviation kind drawn beside the overlapping ADEV.
_KIND_STYLE = {'adev': '1', 'mdev': 'v', 'tdev': '4', 'hdev': '2', 'ohdev': 's',
               'totdev': '^', 'mtotdev': '<', 'htotdev': '>', 'theo1': 'D'}


def draw_deviations(ax, deviations, axes):
    """Draw the extra deviations (kind -> DeviationResult) as small open markers per axis."""
    for kind, dev in (deviations or {}).items():
        if kind == 'tdev':  # a time deviation (unit x s): another quantity, another plot
            continue
        for axis in axes:
            j = dev.axis_index(axis)
            ax.plot(dev.tau, dev.dev[:, j], _KIND_STYLE.get(kind, '.'), ms=3.5, mfc='none',
                    mew=0.7, color=AXIS_COLORS[axis[-1]], alpha=0.8, label=f'{axis} {kind}')


def plot_adev(path, analysis, sensor, denoised=None):
    """
    Allan deviation plot of one sensor ('gyro' or 'accel') saved as PNG at ``path``.

    Returns the Figure (the HTML page shows it as SVG: one drawing for both), None if no axis.
    """
    axes = [a for a in analysis.axes if is_gyro(a) == (sensor == 'gyro')]
    if not axes:
        return None
    fig = Figure(figsize=(8.0, 6.0), dpi=120)  # shown about 1000 px wide on the page
    ax = fig.subplots()
    draw_adev(ax, analysis.result, analysis.fit, axes,
              None if denoised is None else denoised.result, legend_below=True,
              deviations=analysis.deviations)
    name = 'gyroscope' if sensor == 'gyro' else 'accelerometer'
    ax.set_title(f'{name}: overlapping Allan deviation, 68.3 % bands, fitted terms\n'
                 f'{analysis.source} ({analysis.duration_s / 3600:.2f} h at '
                 f'{analysis.rate_hz:.4g} Hz)', fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    return fig


class LiveFigure:
    """
    The allan node's live figure: gyroscope and accelerometer panels side by side, as PNG.

    Each panel is :func:`draw_adev`, the drawing ``analyze``'s plots use.  Object API only (no
    pyplot state), so a worker thread can render while the node keeps taking messages.  The
    figure and its axes are kept between renders and only the data artists are replaced (a
    fresh figure per render cost 30 % more: its log-axis ticks are rebuilt; docs/benchmarks.md).
    """

    def __init__(self, size_px=(1100, 480), dpi=100):
        """Set up an empty figure of ``size_px`` pixels (width, height)."""
        self.size_px = (int(size_px[0]), int(size_px[1]))
        self.figure = Figure(figsize=(self.size_px[0] / dpi, self.size_px[1] / dpi), dpi=dpi)
        # An Agg canvas of its own: savefig then reuses one renderer, and matplotlib's text
        # layout cache (keyed on the renderer) hits from the second render on (-30 % time).
        FigureCanvasAgg(self.figure)
        self.panels = self.figure.subplots(1, 2)
        self.figure.subplots_adjust(left=0.07, right=0.985, bottom=0.11, top=0.87, wspace=0.22)

    def render(self, result, fitted, title):
        """PNG bytes of ``result`` (an AllanResult) and ``fitted`` (FittedModel or None)."""
        for ax in self.panels:
            for artist in [*ax.lines, *ax.collections, *ax.texts]:
                artist.remove()
            if ax.get_legend() is not None:
                ax.get_legend().remove()
        for ax, (name, gyro) in zip(self.panels, (('gyroscopes', True),
                                                  ('accelerometers', False))):
            axes = [a for a in result.axes if is_gyro(a) == gyro]
            ax.set_visible(bool(axes))
            if axes:
                draw_adev(ax, result, fitted, axes)
                ax.relim()
                ax.autoscale_view()
                ax.set_title(name, fontsize=9, y=1.0)  # a fixed y skips a costly layout pass
        self.figure.suptitle(title, fontsize=9)
        buf = io.BytesIO()
        # zlib level 1: about a third of the default's encode time for a slightly larger file
        self.figure.savefig(buf, format='png', pil_kwargs={'compress_level': 1})
        return buf.getvalue()


def plot_timeseries(path, analysis):
    """
    Raw samples per axis against time with outliers (Tukey F=3) marked in black.

    The whole record read (``analysis.samples``, warm-up included): the outlier indices count
    in it.
    """
    axes = list(analysis.axes)
    fig, subplots = plt.subplots(len(axes), 1, figsize=(8.0, 1.5 * len(axes) + 0.8), dpi=100,
                                 sharex=True, squeeze=False)
    raw = analysis.samples.data
    t = analysis.samples.t - analysis.samples.t[0]
    step = max(1, t.size // 20000)  # plot at most ~20k points per axis; outliers all shown
    block = max(int(round(analysis.rate_hz)), 1)
    n_blocks = t.size // block
    for j, axis in enumerate(axes):
        ax = subplots[j, 0]
        color = AXIS_COLORS[axis[-1]] if axis in GYRO_AXES else 'tab:' + {
            'x': 'orange', 'y': 'olive', 'z': 'purple'}[axis[-1]]
        ax.plot(t[::step], raw[::step, j], lw=0.4, color=color, alpha=0.6)
        if n_blocks >= 2:
            means = raw[:n_blocks * block, j].reshape(n_blocks, block).mean(axis=1)
            ax.plot(t[block // 2:n_blocks * block:block], means, lw=0.9, color='k', alpha=0.7)
        idx = analysis.outliers.indices.get(axis, np.zeros(0, dtype=int))
        if idx.size:
            ax.plot(t[idx], raw[idx, j], 'x', color='k', ms=4,
                    label=f'{idx.size} outlier(s)')
            ax.legend(fontsize=6, loc='upper right')
        ax.set_ylabel(f'{axis}\n({sample_unit(axis)})', fontsize=7)
        ax.tick_params(labelsize=7)
    subplots[-1, 0].set_xlabel('time since start (s)')
    subplots[0, 0].set_title(f'raw samples (light), 1-s means (black), Tukey F=3 outliers (x)'
                             f'\n{analysis.source}', fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
