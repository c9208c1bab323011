# noqa: A005 (the module is named for what it writes; the standard html module is not used)
"""
Self-contained HTML pages of ``analyze``, ``fleet`` and ``discrepancy``.

``analyze --out DIR`` writes ``report.html`` (and ``index.html`` for several inputs),
``fleet --out DIR`` ``index.html`` and ``discrepancy --out DIR`` ``report.html``.

The pages are Jinja2 templates (``templates/*.html.j2``) with the one stylesheet
``templates/style.css`` inlined, and figures inline: the Allan deviation plots as SVG drawn from
the very :class:`matplotlib.figure.Figure` saved as PNG beside the page, the other plots as PNG
``data:`` URIs of the files written.  A page is one file with no external reference (no http:,
https: or protocol-relative URL, no external script, font or style), so it opens from a file
manager or a mail attachment.  Python passes data (numbers already formatted by :func:`fmt`, the
one number format the pages print); the templates make the HTML, autoescaped.

Every page is written to a temporary file beside its target and renamed into place, so a failed
run leaves no half-written page.
"""

import base64
import functools
import io
import math
import os
from pathlib import Path
import re
import tempfile

import jinja2
from markupsafe import Markup

from .advice import advice_headline, axis_lines, format_duration, term_words
from .fit_quality import misfit_sentence
from ..core.terms import TERMS
from ..core.units import conventional, IEEE_TERMS, si_unit

TEMPLATES = Path(__file__).with_name('templates')
STYLE = 'style.css'
#: What each file beside the analysis page is for (one line each); export files are described
#: from the exporter registry.
FILE_PURPOSES = {
    'report.json': 'the whole report, machine-readable: SI units, continuous-time '
                   'coefficients, 68.3 % intervals (the schema is in docs/interfaces.md)',
    'imu.yaml': 'Kalibr IMU noise file (noise densities and random walks, worst axis per '
                'sensor, continuous-time): give it to Kalibr or a VIO that reads Kalibr files',
    'allan_results.csv': 'coefficients per term (rows) and axis (columns) with interval bounds, '
                         'for a spreadsheet (thesis layout)',
    'adev_gyro.png': 'the gyroscope Allan deviation plot shown on this page, as an image',
    'adev_accel.png': 'the accelerometer Allan deviation plot shown on this page, as an image',
    'timeseries.png': 'the raw samples per axis with outliers marked, as an image',
    'dynamic_gyro.png': 'the dynamic Allan deviation of the gyroscopes, as an image',
    'dynamic_accel.png': 'the dynamic Allan deviation of the accelerometers, as an image',
    'denoised_bag': 'rosbag2 (MCAP) with the wavelet-denoised samples on imu/data_denoised',
}
#: Captions of the PNG figures shown inline as data: URIs.
PNG_CAPTIONS = {
    'timeseries.png': 'Raw samples per axis (light), their 1-s means (black) and the Tukey '
                      'F = 3 outliers (x).',
    'dynamic_gyro.png': 'Dynamic Allan deviation of the gyroscopes: the deviation over window '
                        'time and averaging time, changes marked.',
    'dynamic_accel.png': 'Dynamic Allan deviation of the accelerometers: the deviation over '
                         'window time and averaging time, changes marked.',
}
ADEV_CAPTION = ('Dots: measured overlapping Allan deviation per axis, shaded: its 68.3 % '
                'interval; dashed: each fitted term alone; solid: the fitted model (their sum, '
                'with the lines fitted beside it); a band in the colour of an axis from the left: '
                'averaging times its fit left out (a resonance of the sensor shapes them); '
                'grey fan: the slopes ' + ', '.join(f'{TERMS[t].adev_slope} ({term_words(t)})'
                                                    for t in IEEE_TERMS) + '.')


def fmt(value, digits=4):
    """Return the text the pages print for a number: ``digits`` significant digits, '-' if none."""
    if value is None or isinstance(value, bool):
        return '-' if value is None else str(value).lower()
    try:
        value = float(value)
    except (TypeError, ValueError):
        return str(value)
    return f'{value:.{digits}g}' if math.isfinite(value) else '-'


def _duration(seconds):
    if seconds is None:
        return '-'
    return f'{fmt(seconds)} s ({format_duration(seconds)[len("about "):]})' \
        if seconds >= 90 else f'{fmt(seconds)} s'


@functools.lru_cache(maxsize=1)
def environment():
    """Return the Jinja2 environment of the package's templates (autoescaped HTML)."""
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)), autoescape=True,
                             trim_blocks=True, lstrip_blocks=True,
                             undefined=jinja2.StrictUndefined)
    env.filters['num'] = fmt
    env.filters['words'] = term_words
    env.filters['duration'] = _duration
    env.filters['is_mapping'] = lambda v: isinstance(v, dict)
    env.filters['is_list'] = lambda v: isinstance(v, (list, tuple))
    return env


def stylesheet():
    """Return the pages' CSS (the one file ``templates/style.css``), ready to inline."""
    return Markup((TEMPLATES / STYLE).read_text(encoding='utf-8'))


_SVG_START = re.compile(r'<svg\b[^>]*>', re.S)


def svg_markup(figure):
    """
    Return a Matplotlib figure as inline SVG markup for an HTML page.

    Text is drawn as paths (no font needed); the XML prolog, DOCTYPE, metadata and namespace
    declarations are dropped (an HTML parser needs none, and they are http: URLs), and the size
    is left to the stylesheet (the viewBox keeps the aspect ratio).
    """
    buf = io.StringIO()
    figure.savefig(buf, format='svg', metadata={'Date': None, 'Creator': None, 'Format': None,
                                                'Type': None})
    text = buf.getvalue()
    text = text[text.index('<svg'):]
    text = re.sub(r'<metadata>.*?</metadata>', '', text, flags=re.S)
    head = _SVG_START.match(text).group(0)
    view_box = re.search(r'viewBox="([^"]+)"', head).group(1)
    text = (f'<svg viewBox="{view_box}" class="figure" role="img" version="1.1">'
            + text[len(head):])
    return Markup(text)


def png_data_uri(path):
    """Return a PNG file as a ``data:image/png;base64,...`` URI."""
    data = Path(path).read_bytes()
    return 'data:image/png;base64,' + base64.b64encode(data).decode('ascii')


def render(template, **context):
    """Render one page template with the stylesheet; returns the HTML text."""
    return environment().get_template(template).render(css=stylesheet(), **context)


def write_page(path, template, **context):
    """Render ``template`` and write it to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    text = render(template, **context)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', dir=path.parent)
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as stream:
            stream.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


# ---------------------------------------------------------------- the analysis page


def coefficient_rows(report):
    """
    Rows of the coefficient table: per axis and detected term, every number as the page prints.

    Each row: ``axis, term, letter, value, ci (lo, hi), unit, conv_value, conv_ci, conv_unit``
    and ``extras`` (Gauss-Markov ``tau_c``, sinusoid ``frequency_hz``: name, value, ci, unit).
    """
    rows = []
    for axis, entry in report['axes'].items():
        terms = entry.get('terms', {})
        if not terms:
            rows.append({'axis': axis, 'term': None})
        for term, t in terms.items():
            lo, hi = t.get('ci', [None, None])
            conv = t.get('conventional') or {}
            conv_ci = conv.get('ci') or [None, None]
            spec = TERMS.get(term)
            extras = [{'name': name, 'value': fmt(t[name].get('value')),
                       'ci': [fmt(c) for c in t[name].get('ci', [None, None])],
                       'unit': t[name].get('unit', '')}
                      for name in [spec.position] if spec and isinstance(t.get(name), dict)]
            letter = spec.symbol if spec else ''
            rows.append({'axis': axis, 'term': term, 'letter': letter,
                         'value': fmt(t.get('value')), 'ci': [fmt(lo), fmt(hi)],
                         'unit': t.get('unit', ''), 'conv_value': fmt(conv.get('value')),
                         'conv_ci': [fmt(conv_ci[0]), fmt(conv_ci[1])],
                         'conv_unit': conv.get('unit', ''), 'extras': extras})
    return rows


def _limits(report):
    """Undetected terms: 95 % upper limits per axis (SI and conventional)."""
    out = []
    for axis, terms in (report.get('upper_limits') or {}).items():
        for term, value in terms.items():
            if value is None:
                continue
            conv, conv_unit = conventional(axis, term, value)
            out.append({'axis': axis, 'term': term, 'value': fmt(value),
                        'unit': si_unit(axis, term), 'conv_value': fmt(conv),
                        'conv_unit': conv_unit})
    return out


def advice_words(advice, moving=(), alternatives=False):
    """
    Return the recording advice (report.json's ``advice`` block) as a headline and lines.

    The console's and the node's words (:mod:`.advice`): the headline for the record, a line
    per axis.  ``moving`` (axes) and ``alternatives`` (term sets the fit leaves open) come
    from the rest of the report, for an advice block that lacks them.
    """
    if not advice and not moving:
        return {'headline': None, 'lines': []}
    doc = dict(advice or {}, moving=list(moving) or (advice or {}).get('moving') or [])
    headline = advice_headline(doc, alternatives)
    lines = [] if doc['moving'] else [line + '.' for line in axis_lines(doc).values()]
    return {'headline': headline[0].upper() + headline[1:], 'lines': lines}


def _file_list(folder):
    """Files written beside the page (relative paths), with one line on what each is for."""
    from .exporters import EXPORTERS
    by_file = {f: e for e in EXPORTERS.values() for f in e.files}
    folder = Path(folder)
    out = []
    for path in sorted(folder.iterdir()):
        name = path.name
        if name.startswith('.') or name == 'report.html':
            continue
        if path.is_dir() and name == 'export':
            for sub in sorted(path.iterdir()):
                e = by_file.get(sub.name)
                what = (f'{e.consumer}: {e.time_base} values ({e.conversion})' if e else
                        'model export')
                out.append({'href': f'export/{sub.name}', 'name': f'export/{sub.name}',
                            'what': what})
            continue
        what = FILE_PURPOSES.get(name, 'written by this analysis')
        out.append({'href': name + ('/' if path.is_dir() else ''),
                    'name': name + ('/' if path.is_dir() else ''), 'what': what})
    return out


def _alternatives(report):
    out = []
    for axis, entry in report['axes'].items():
        alts = (entry.get('fit') or {}).get('alternatives')
        if alts and len(alts) > 1:
            out.append({'axis': axis, 'selected': [term_words(t) for t in alts[0]],
                        'others': [[term_words(t) for t in a] for a in alts[1:]]})
    return out


def _deviations(report):
    out = []
    for axis, entry in report['axes'].items():
        for kind, dev in (entry.get('deviations') or {}).items():
            tau = [t for t in dev.get('tau', []) if t is not None]
            out.append({'axis': axis, 'kind': kind, 'points': len(tau),
                        'tau': [fmt(tau[0]), fmt(tau[-1])] if tau else ['-', '-']})
    return out


def _quality(report):
    """Per axis: the adequacy verdict, the fitted span and why, the misfit in words."""
    rows = []
    for axis, entry in report['axes'].items():
        fit = entry.get('fit') or {}
        adequacy = fit.get('adequacy')
        if adequacy is None:
            continue
        span = fit.get('tau_range_s') or [None, None]
        tested = adequacy.get('tested', True)
        rows.append({'axis': axis, 'adequate': adequacy['adequate'] or not tested,
                     'tested': tested, 'p': fmt(adequacy['p'], 2),
                     'chi2': fmt(adequacy['chi2'], 3), 'dof': adequacy['dof'],
                     'span': [fmt(span[0], 3), fmt(span[1], 4)],
                     'limited_by': fit.get('tau_range_limited_by'),
                     'words': (None if adequacy['adequate'] or not tested
                               else misfit_sentence(axis, adequacy)),
                     'lines': [f'{fmt(ln["frequency_hz"], 3)} Hz' for ln in fit.get('lines', [])]})
    return rows


def _sensor(report):
    """Per axis: what the samples say about the sensor's processing (report.json ``sensor``)."""
    rows = []
    for axis, s in ((report.get('sensor') or {}).get('axes') or {}).items():
        lag = s.get('lag_correlation') or []
        rows.append({'axis': axis, 'unit': s.get('unit', ''),
                     'resolution': fmt(s.get('resolution')), 'distinct': s.get('distinct_values'),
                     'repeated': fmt(100 * s['repeated_fraction'], 3)
                     if s.get('repeated_fraction') is not None else '-',
                     'quantization': s.get('quantization') or '-',
                     'lag1': fmt(lag[0], 3) if lag else '-',
                     'filter_length': s.get('filter_length'),
                     'bandwidth': fmt(s.get('bandwidth_hz'), 3),
                     'lines': ', '.join(f'{fmt(ln["frequency_hz"], 3)} Hz'
                                        for ln in s.get('lines', [])) or '-',
                     'humps': ', '.join(f'{fmt(h["frequency_range_hz"][0], 3)}-'
                                        f'{fmt(h["frequency_range_hz"][1], 3)} Hz'
                                        for h in s.get('humps', [])) or '-'})
    return rows


def analysis_context(report, folder, figures=None):
    """
    Everything the analysis page shows, from the report dict and the files in ``folder``.

    ``figures``: ``{'gyro': Figure, 'accel': Figure}`` (the Allan deviation plots, shown as
    SVG); other PNG files in ``folder`` are shown as data: URIs.
    """
    folder = Path(folder)
    names = {'gyro': 'Gyroscopes', 'accel': 'Accelerometers', 'timeseries': 'Time series',
             'dynamic_gyro': 'Dynamic Allan deviation, gyroscopes',
             'dynamic_accel': 'Dynamic Allan deviation, accelerometers'}
    figures = {k: f for k, f in (figures or {}).items() if hasattr(f, 'savefig')}
    svgs = [{'title': names.get(k, k), 'svg': svg_markup(fig), 'file': f'adev_{k}.png',
             'caption': ADEV_CAPTION} for k, fig in figures.items()]
    # any other PNG (and an Allan plot whose Figure was not handed over) as a data: URI
    shown = {f'adev_{k}.png' for k in figures}
    pngs = [{'title': names.get(name[:-4].removeprefix('adev_'), name[:-4].replace('_', ' ')),
             'uri': png_data_uri(folder / name), 'file': name,
             'caption': ADEV_CAPTION if name.startswith('adev_') else PNG_CAPTIONS.get(name, '')}
            for name in sorted(os.listdir(folder)) if name.endswith('.png') and name not in shown]
    pngs.sort(key=lambda f: not f['file'].startswith('adev_'))
    verdict = report.get('verdict', {})
    moving = [a for a, m in (verdict.get('motion') or {}).items()
              if isinstance(m, dict) and m.get('moving')]
    alternatives = _alternatives(report)
    return {
        'report': report, 'coefficients': coefficient_rows(report), 'limits': _limits(report),
        'advice': advice_words(report.get('advice'), moving, bool(alternatives)),
        'svgs': svgs, 'pngs': pngs, 'files': _file_list(folder), 'alternatives': alternatives,
        'deviations': _deviations(report), 'moving': moving, 'quality': _quality(report),
        'sensor': _sensor(report),
    }


def write_analysis_page(folder, report, figures=None):
    """Write ``folder/report.html`` of one analysis (after the other files are in ``folder``)."""
    return write_page(Path(folder) / 'report.html', 'analysis.html.j2',
                      **analysis_context(report, folder, figures))


def write_batch_index(out_dir, outcomes, out_dirs):
    """
    Write ``out_dir/index.html`` listing the inputs of a run of several, each linking its page.

    ``outcomes``: the :func:`imu_allan.cli.batch.analyze_task` results; ``out_dirs``: input ->
    its sub-folder.
    """
    out_dir = Path(out_dir)
    rows = []
    for o in outcomes:
        row = {'input': o['input'], 'ok': o['ok'], 'error': o.get('error')}
        sub = out_dirs.get(o['input'])
        if o['ok'] and sub and (Path(sub) / 'report.html').is_file():
            row['href'] = os.path.relpath(Path(sub) / 'report.html', out_dir)
        if o['ok']:
            rep = o['report']
            kal = rep.get('kalibr', {})
            g, a = kal.get('gyroscope_noise_density'), kal.get('accelerometer_noise_density')
            row.update(samples=rep['n_samples'], rate=fmt(rep['sample_rate_hz']),
                       hours=fmt(rep['duration_s'] / 3600, 3),
                       static=rep['verdict']['static'],
                       gyro_n=fmt(conventional('gyro_x', 'white_noise', g)[0]) if g else '-',
                       accel_n=fmt(conventional('accel_x', 'white_noise', a)[0]) if a else '-',
                       record_more=(rep.get('advice') or {}).get('record_more_s'))
        rows.append(row)
    out_dir.mkdir(parents=True, exist_ok=True)
    return write_page(out_dir / 'index.html', 'batch_index.html.j2', rows=rows,
                      failed=sum(not r['ok'] for r in rows))


# ---------------------------------------------------------------- the fleet page

#: The fleet flags in words (what each kind means; the thresholds from history/trends.py).
FLAG_MEANINGS = {
    'history': 'its latest value left its own history: the 68.3 % interval of the latest '
               'record lies wholly outside the band median ± {k} spreads of its earlier records '
               '(spread: the larger of their robust standard deviation and their typical '
               'interval half-width)',
    'fleet': "its latest worst-axis value is above the fleet's {p}th percentile (every other "
             'record of every IMU, same sensor and term) by more than its own uncertainty',
}


def _source_href(path, out_dir):
    """Return a link to a measurement's source, relative to the page (opened from a folder)."""
    try:
        return os.path.relpath(path, out_dir)
    except ValueError:  # another drive (Windows): an absolute file: URI
        return Path(path).as_uri()


def fleet_imus(report, imus, out_dir):
    """
    Return the IMUs of a fleet report, flagged ones first, each with its records newest first.

    Per record the worst-axis N and B of each sensor with their 68.3 % intervals, in
    conventional units (as printed by :func:`fmt`), and a link to the record's source.
    """
    from ..history.trends import FLEET_PERCENTILE, K_SPREAD, SENSORS, TREND_TERMS, WORST
    columns = [{'sensor': s, 'term': t, 'letter': TREND_TERMS[t],
                'unit': conventional(f'{s}_x', t, 1.0)[1]} for s in SENSORS for t in TREND_TERMS]
    out = []
    for entry in report['imus']:
        imu = imus[entry['imu_id']]
        points = {}
        for c in columns:
            s = imu.series.get((c['sensor'], c['term'], WORST))
            for k in range(len(s.value) if s else 0):
                factor = conventional(s.axes[k], c['term'], 1.0)[0]
                points[(c['sensor'], c['term'], s.start[k], s.inputs[k])] = {
                    'axis': s.axes[k], 'value': fmt(s.value[k] * factor),
                    'ci': [fmt(s.low[k] * factor), fmt(s.high[k] * factor)]}
        flagged_inputs = {f['input'] for f in imu.flags}
        rows = [{'start': f'{start:%Y-%m-%d %H:%M}', 'input': inp,
                 'href': _source_href(inp, out_dir), 'flagged': inp in flagged_inputs,
                 'cells': [points.get((c['sensor'], c['term'], start, inp)) for c in columns]}
                for start, inp in reversed(imu.records)]
        words = {k: text.format(k=f'{K_SPREAD:g}', p=f'{FLEET_PERCENTILE:g}')
                 for k, text in FLAG_MEANINGS.items()}
        flags = [{'why': f['why'], 'kind': f['kind'], 'meaning': words.get(f['kind'], '')}
                 for f in imu.flags]
        plot = Path(entry['plot'])
        out.append({'imu_id': entry['imu_id'], 'records': entry['records'],
                    'first': entry['first_utc'][:16].replace('T', ' '),
                    'latest': entry['latest_utc'][:16].replace('T', ' '),
                    'flagged': entry['flagged'], 'flags': flags, 'rows': rows,
                    'plot_uri': png_data_uri(plot) if plot.is_file() else None,
                    'plot_file': plot.name, 'anchor': re.sub(r'[^A-Za-z0-9_-]', '_',
                                                             entry['imu_id'])})
    out.sort(key=lambda e: (not e['flagged'], e['imu_id']))
    return columns, out


def write_fleet_page(out_dir, report, imus):
    """Write ``out_dir/index.html`` of a fleet report (after its PNGs and fleet.json)."""
    columns, entries = fleet_imus(report, imus, out_dir)
    return write_page(Path(out_dir) / 'index.html', 'fleet.html.j2', report=report,
                      columns=columns, imus=entries,
                      n_flagged=sum(e['flagged'] for e in entries))


# ---------------------------------------------------------------- the discrepancy page

#: What each discrepancy file is for.
DISCREPANCY_FILES = {
    'report.json': 'the whole report, machine-readable (SI units, continuous-time)',
    'final_model.yaml': 'the corrected noise model (SI, continuous-time): give it to '
                        'imu_allan.simulate or discrepancy --model',
    'corrected.sdf': 'the Gazebo / PX4 simulator file given as --model, with the missing '
                     'effects added: drop it in place of the original',
    'gap_per_step.png': 'the gap per step, as an image',
    'overview.png': 'every axis, initial and final model bands, as an image',
}


def _param_rows(parameters, prefix=''):
    rows = []
    for name, entry in (parameters or {}).items():
        label = prefix + str(name).replace('_', ' ')
        if isinstance(entry, dict) and 'value' in entry:
            ci = entry.get('ci') or [None, None]
            rows.append({'name': label, 'value': fmt(entry['value']),
                         'ci': [fmt(ci[0]), fmt(ci[1])], 'unit': entry.get('unit', '')})
        elif isinstance(entry, dict):
            rows += _param_rows(entry, f'{prefix}{term_words(name)}: ')
        else:
            rows.append({'name': label, 'value': fmt(entry), 'ci': None, 'unit': ''})
    return rows


def _model_cell(axis, term, value):
    """One term of one axis of a model: a number with its SI unit, or its parameters."""
    if value is None:
        return None
    if isinstance(value, (int, float)):
        try:
            unit = si_unit(axis, term)
        except (KeyError, ValueError):
            unit = ''
        return {'text': fmt(value), 'unit': unit}
    return {'value': value}


def discrepancy_context(report, out_dir):
    """Everything the discrepancy page shows, from its report dict and the files in ``out_dir``."""
    out_dir = Path(out_dir)
    steps = [{**s, 'number': k + 1, 'params': _param_rows(s.get('parameters')),
              'plot': next((p for p in sorted(os.listdir(out_dir))
                            if p.startswith(f'step{k + 1:02d}_') and p.endswith('.png')), None)}
             for k, s in enumerate(report.get('steps', []))]
    for s in steps:
        s['plot_uri'] = png_data_uri(out_dir / s['plot']) if s['plot'] else None
    pngs = [{'title': title, 'uri': png_data_uri(out_dir / name), 'file': name,
             'caption': caption}
            for name, title, caption in (
                ('overview.png', 'Every axis', 'Measured Allan deviation (black, 68 % interval) '
                 'with the initial model (red) and the final model (blue), each a 95 % band of '
                 'simulated runs through the same estimator.'),
                ('gap_per_step.png', 'The gap per step', 'The gap of each axis after each '
                 'effect added; below the green line the model and the data agree.'))
            if (out_dir / name).is_file()]
    sdf = out_dir / 'corrected.sdf'
    files = [{'name': n, 'what': w} for n, w in DISCREPANCY_FILES.items()
             if (out_dir / n).is_file()]
    files += [{'name': s['plot'], 'what': f'step {s["number"]} ({s["axis"]} + '
                                          f'{term_words(s["effect"])}), as an image'}
              for s in steps if s['plot']]
    model_terms = sorted({t for terms in report.get('final_model', {}).values() for t in terms},
                         key=lambda t: list(TERMS).index(t) if t in TERMS else 99)
    model_rows = [{'axis': axis, 'cells': [_model_cell(axis, t, terms.get(t))
                                           for t in model_terms]}
                  for axis, terms in report.get('final_model', {}).items()]
    return {'report': report, 'steps': steps, 'pngs': pngs, 'files': files,
            'model_terms': model_terms, 'model_rows': model_rows,
            'sdf_text': sdf.read_text(encoding='utf-8') if sdf.is_file() else None}


def write_discrepancy_page(out_dir, report):
    """Write ``out_dir/report.html`` of a discrepancy run (after its other files)."""
    return write_page(Path(out_dir) / 'report.html', 'discrepancy.html.j2',
                      **discrepancy_context(report, out_dir))
