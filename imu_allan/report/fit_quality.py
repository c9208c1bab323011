"""
What the reports say about a fit's quality and the sensor behind it: adequacy, span, processing.

Renders (never computes) :class:`~imu_allan.core.fit.adequacy.Adequacy`, the fitted span
(:class:`~imu_allan.core.fit.tau_range.TauRange`) and the sensor's processing
(:class:`~imu_allan.core.sensor.measure.SensorReport`) for report.json, the console, the HTML page
and the node's diagnostics, in one wording.
"""

import math

from ..core.live.health import Health, OK, WARN
from ..core.terms import TERMS
from ..core.units import conventional, is_gyro, STANDARD_GRAVITY


def fit_json(fitted, axis):
    """Return the quality entries of report.json's ``axes.<axis>.fit`` (adequacy, span)."""
    fit = fitted.fits.get(axis)
    if fit is None:
        return {}
    out = {}
    if fit.adequacy is not None:
        out['adequacy'] = fit.adequacy.to_json()
    span = fit.tau_range
    if span is not None:
        out['tau_range_s'] = span.to_json()
        out['tau_range_limited_by'] = span.limited_by
        out['filter_moment'] = float(span.filter_moment)  # measured (or the device's)
    if fit.filter_moment_fitted is not None:
        out['filter_moment_fitted'] = float(fit.filter_moment_fitted)
    out['lines'] = [{'frequency_hz': float(f), 'amplitude': float(a)}
                    for f, a in sorted(fit.lines.items())]
    return out


#: What an untested adequacy says (too few averaging times for the test).
NOT_TESTED = 'adequacy not tested: too few averaging times yet'


def inadequate(fitted, axis):
    """Return the adequacy of ``axis`` when the test rejects its model, else None."""
    adequacy = fitted.adequacy(axis) if fitted is not None else None
    return adequacy if adequacy is not None and adequacy.rejected else None


def misfit_sentence(axis, adequacy):
    """
    Return one sentence for people: where the model misses, by how much, what bends it.

    ``adequacy``: report.json's ``fit.adequacy`` of ``axis`` (a rejected model).  "gyro_z: the
    model does not describe 0.01-0.05 s (measured 1.6x the model): a 19 Hz line".
    """
    widened = f'; intervals widened {adequacy["interval_scale"]:.3g}x'
    if not adequacy['misfit']:
        return (f'{axis}: the model does not describe the curve (adequacy p = '
                f'{adequacy["p"]:.2g}){widened}')
    worst = adequacy['misfit'][0]
    lo, hi = worst['tau_s']
    span = f'{lo:.3g} s' if math.isclose(lo, hi) else f'{lo:.3g}-{hi:.3g} s'
    text = (f'{axis}: the model does not describe {span} (measured {worst["ratio"]:.2g}x the '
            f'model)')
    if worst['effect']:
        text += f': {worst["effect"]}'
    more = len(adequacy['misfit']) - 1
    if more:
        text += f'; {more} more span{"s" if more > 1 else ""}'
    return text + widened


def adequacy_lines(fitted):
    """Console lines: one per axis whose model the adequacy test rejects (p < 0.001)."""
    return [misfit_sentence(axis, ad.to_json()) for axis in fitted.axes
            if (ad := inadequate(fitted, axis)) is not None]


def adequacy_health(fitted, axes, prefix=''):
    """
    Return the ``/diagnostics`` records of the fit's adequacy, one per axis fitted.

    OK, or WARN saying where the model misses (:func:`misfit_sentence`); values: p, chi^2,
    dof, the intervals' widening and the fitted span.
    """
    out = []
    for axis in axes:
        adequacy = fitted.adequacy(axis) if fitted is not None else None
        if adequacy is None:
            continue
        span = fitted.tau_range(axis)
        values = {'p': adequacy.p, 'chi2': adequacy.chi2, 'dof': adequacy.dof,
                  'interval_scale': adequacy.scale}
        if span is not None:
            values.update({'tau_lo_s': span.lo, 'tau_hi_s': span.hi,
                           'limited_by': span.limited_by or 'none'})
        if not adequacy.tested:
            out.append(Health(f'{prefix}{axis} model', OK, NOT_TESTED, values))
        elif adequacy.adequate:
            out.append(Health(f'{prefix}{axis} model', OK,
                              f'the noise model describes the curve (p = {adequacy.p:.2g})',
                              values))
        else:
            out.append(Health(f'{prefix}{axis} model', WARN,
                              misfit_sentence(axis, adequacy.to_json()), values))
    return out


_WHY = {'filter': "the sensor's filter correlates the samples",
        'resonance': 'a resonance shapes the curve', 'asked': 'as asked'}


def span_line(fitted):
    """Return the fitted span in one line, and why an axis starts later ('' if none does)."""
    spans = {a: fitted.fits[a].tau_range for a in fitted.axes
             if fitted.fits[a].tau_range is not None}
    late = {a: s for a, s in spans.items() if s.limited_by not in (None, 'filter')}
    filtered = [a for a, s in spans.items() if s.filter_moment > 0]
    if not late and not filtered:
        return ''
    parts = []
    if filtered:
        which = 'every axis' if len(filtered) == len(spans) else ', '.join(filtered)
        known = all(spans[a].filter_known for a in filtered)
        how = "the device's window: its deficit N's" if known else 'its deficit fitted'
        parts.append(f"the sensor's filter correlates the samples on {which} ({how})")
    by_reason = {}
    for axis, span in late.items():
        by_reason.setdefault(span.limited_by, []).append(f'{axis} from {span.lo:.2g} s')
    for reason, axes in by_reason.items():
        parts.append(f'fitted {", ".join(axes)} ({_WHY[reason]} below)')
    return 'fit: ' + '; '.join(parts)


def line_sentence(fitted):
    """Return the lines fitted beside the noise model, per axis ('' if none)."""
    parts = []
    for axis in fitted.axes:
        fit = fitted.fits[axis]
        lines = dict(fit.lines)
        if 'sinusoid' in fit.terms:
            amplitude, frequency = TERMS['sinusoid'].unpack(fit.terms['sinusoid'])
            lines[frequency] = amplitude
        if lines:
            parts.append(f'{axis} ' + ', '.join(
                f'{f:.3g} Hz ({_amplitude(axis, a)})' for f, a in sorted(lines.items())))
    return "lines fitted (the sensor's, not noise): " + '; '.join(parts) if parts else ''


def _amplitude(axis, value):
    conv, unit = conventional(axis, 'sinusoid', value)
    return f'{conv:.3g} {unit}'


def sensor_json(report):
    """report.json ``sensor``: :meth:`~imu_allan.core.sensor.measure.SensorReport.to_json`."""
    return report.to_json()


def sensor_sentence(report):
    """Return the sensor's processing in one line: LSB, repeats, filter, per sensor."""
    parts = []
    for sensor in ('gyro', 'accel'):
        axes = [ax for name, ax in report.axes.items() if is_gyro(name) == (sensor == 'gyro')]
        if not axes:
            continue
        bits = []
        lsb = [ax.resolution for ax in axes if ax.resolution]
        if lsb:
            conv, unit = _lsb(axes[0].axis, max(lsb))
            bits.append(f'LSB {conv:.3g} {unit}')
            coarse = [ax.axis for ax in axes if ax.quantization == 'coarse']
            if coarse:
                bits.append('coarse quantization on ' + ', '.join(coarse))
        repeats = [100 * ax.repeated_fraction for ax in axes if ax.repeated_fraction is not None]
        if repeats:
            bits.append(f'{_range(repeats, "{:.0f}")} % repeated samples')
        rho = [ax.lag_correlation[0] for ax in axes if ax.lag_correlation]
        if rho:
            bits.append(f'lag-1 correlation {_range(rho, "{:.2f}")}')
        if bits:
            parts.append(f'{sensor} ' + ', '.join(bits))
    return 'sensor: ' + '; '.join(parts) if parts else ''


def _range(values, form):
    """Return 'lo-hi' of ``values`` in ``form``, or one number where both read alike."""
    lo, hi = form.format(min(values)), form.format(max(values))
    return lo if lo == hi else f'{lo}-{hi}'


def _lsb(axis, value):
    """Return an LSB in the units people use for it (deg/s, mg)."""
    if is_gyro(axis):
        return math.degrees(value), 'deg/s'
    return value / STANDARD_GRAVITY * 1e3, 'mg'
