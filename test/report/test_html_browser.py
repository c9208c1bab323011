"""
The HTML pages in a real headless Chromium.

``analyze --out`` (one input, and the index of several), ``fleet --out`` and
``discrepancy --out``.

Each page is opened from ``file://`` with the network emulated offline, 1280 px wide, and must:
load with no console error and no request other than file: and data: (the page is one
self-contained file); decode every image (naturalWidth > 0) and draw every inline SVG (a
non-zero bounding box); give a screenshot that is not blank (its pixels: enough non-white ink
and many distinct colours, as plots and tables give); and show every coefficient of the
report in the page's own number format (:func:`imu_allan.report.html.fmt`).  A static check
finds no http:, https: or protocol-relative reference and no external script, style or font.

The browser is Debian's ``chromium`` (``make test`` installs it with apt when it can); without
one the tests skip and say so.  One browser serves the module (a page loads in well under a
second); the inputs are short simulated recordings (fixed seeds).  Most of the module's time
(about 70 s of CPU here) is the analyses and the Dask cluster of the several-inputs test.
"""

import io
import json
import re
import shutil

from conftest import run_command
from imu_allan import NoiseModel, simulate
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
from imu_allan.report.html import fmt, write_analysis_page
import matplotlib.image
import numpy as np
import pytest

from .chromium import Chromium, find_chromium

pytestmark = [pytest.mark.browser, pytest.mark.ros]

MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.0e-4, 'bias_instability': 1.0e-4},
                              'accel': {'white_noise': 8.0e-4, 'bias_instability': 5.0e-4}})
RATE = 100.0
#: References a self-contained page must not hold (in attributes, CSS url() or anywhere).
EXTERNAL = re.compile(r'https?:|(?:src|href)\s*=\s*["\']?//|url\(\s*["\']?//|<script[^>]+src|'
                      r'<link[^>]+stylesheet|@import|@font-face', re.I)


@pytest.fixture(scope='module')
def browser():
    """One headless Chromium for the module (skip, saying why, when there is none)."""
    path = find_chromium()
    if path is None:
        pytest.skip('no Chromium browser found (Debian: apt-get install chromium; make test '
                    'installs it when run as root with apt)')
    with Chromium(path) as chromium:
        yield chromium


def _csv(path, n, seed):
    data = simulate(MODEL, n, RATE, seed=seed)
    write_csv(path, Samples(t=1.7e9 + np.arange(n) / RATE, data=data))
    return path


@pytest.fixture(scope='module')
def analysis_dir(tmp_path_factory):
    """``analyze --out`` on 15 min of six simulated axes."""
    tmp = tmp_path_factory.mktemp('analyze')
    out = tmp / 'report'
    proc = run_command('analyze', _csv(tmp / 'still.csv', 90_000, 3), '--out', out,
                       '--export', 'kalibr,gtsam')
    assert proc.returncode == 0, proc.stderr
    return out


def _check_page(browser, path, figures=True):
    """Open ``path``; run every check common to the pages; return the page's text."""
    html = path.read_text(encoding='utf-8')
    assert not EXTERNAL.search(html), EXTERNAL.search(html).group(0)
    page = browser.open_page(path.resolve().as_uri())
    try:
        assert page.console_errors() == []
        left = [u for u in page.requests() if not u.startswith(('file:', 'data:'))]
        assert left == [], left
        # every attribute reference resolves to this file's folder or a data: URI
        refs = page.evaluate('[...document.querySelectorAll("[src],[href]")]'
                             '.map(e => e.src || e.href)')
        assert all(r.startswith(('file:', 'data:')) for r in refs), refs
        images = page.evaluate('[...document.images].map(i => i.complete && i.naturalWidth)')
        assert all(w and w > 0 for w in images), images
        boxes = page.evaluate('[...document.querySelectorAll("svg")].map(s => {'
                              'const b = s.getBBox(); return b.width * b.height; })')
        assert all(a > 0 for a in boxes), boxes
        assert images or boxes or not figures, 'a page without a figure'
        width = page.evaluate('document.documentElement.scrollWidth')
        assert width <= 1280, f'the page is {width} px wide: it scrolls sideways at 1280 px'
        pixels = matplotlib.image.imread(io.BytesIO(page.screenshot()), format='png')[..., :3]
        ink = np.mean(pixels.mean(axis=2) < 0.9)
        rgb = (pixels * 255).astype(np.uint32)
        colours = np.unique((rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]).size
        assert pixels.shape[1] == 1280 and pixels.shape[0] > (600 if figures else 150)
        # text, table rules and plots: several % ink, hundreds of colours (anti-aliased
        # curves in a dozen hues); a blank or unstyled-error page has a handful
        assert ink > 0.02 and colours > (200 if figures else 20), (ink, colours)
        return page.evaluate('document.body.innerText')
    finally:
        page.close()


def _numbers(entry):
    """Return the value and interval of a coefficient entry, SI and conventional, as printed."""
    out = [entry['value'], *entry['ci']]
    conv = entry.get('conventional')
    if conv:
        out += [conv['value'], *conv['ci']]
    return [fmt(x) for x in out]


@pytest.mark.slow
def test_analysis_page(browser, analysis_dir):
    """report.html: loads clean, draws, and shows every coefficient of report.json."""
    report = json.loads((analysis_dir / 'report.json').read_text())
    text = _check_page(browser, analysis_dir / 'report.html')
    missing = [(axis, term, x) for axis, a in report['axes'].items()
               for term, entry in a['terms'].items() for x in _numbers(entry)
               if x not in text]
    assert not missing, missing
    assert sum(len(a['terms']) for a in report['axes'].values()) >= 6
    assert 'continuous-time' in text
    for name in ('imu.yaml', 'report.json', 'export/kalibr_imu.yaml', 'adev_gyro.png'):
        assert name in text  # the files beside it, each listed
    assert fmt(report['n_samples']) in text or str(report['n_samples']) in text


@pytest.mark.slow
def test_several_inputs_index(browser, tmp_path):
    """Two inputs: one page each, and index.html linking both (checked in the browser)."""
    a = _csv(tmp_path / 'first.csv', 12_000, 5)
    b = _csv(tmp_path / 'second.csv', 12_000, 6)
    out = tmp_path / 'runs'
    proc = run_command('analyze', a, b, '--out', out, '--workers', '1', '--quiet', timeout=300)
    assert proc.returncode == 0, proc.stderr
    pages = sorted(out.glob('*/report.html'))
    assert [p.parent.name for p in pages] == ['first_csv', 'second_csv']
    text = _check_page(browser, out / 'index.html', figures=False)
    for csv in (a, b):
        assert str(csv) in text
    page = browser.open_page((out / 'index.html').resolve().as_uri())
    try:
        links = page.evaluate('[...document.querySelectorAll("a")].map(a => a.href)'
                              '.filter(h => h.endsWith("report.html"))')
    finally:
        page.close()
    assert sorted(links) == [p.resolve().as_uri() for p in pages]


@pytest.fixture(scope='module')
def fleet_out(tmp_path_factory):
    """
    ``fleet --out`` on a history of 3 IMUs x 6 weekly one-minute records (2 axes, 50 Hz).

    robot1's white noise is 30 % higher in its last record (about 20 of its interval
    half-widths): its history flag is certain, so the page has a flagged IMU to put first.
    """
    from imu_allan.cli.batch import History
    from imu_allan.core.analysis import AnalysisOptions, analyze_samples
    from imu_allan.history.db import utc
    from imu_allan.report.json_report import analysis_to_json
    tmp = tmp_path_factory.mktemp('fleet')
    db = tmp / 'history.duckdb'
    history = History(db)
    options = AnalysisOptions(terms=['white_noise', 'bias_instability'])
    n, rate, t0, week = 3000, 50.0, 1_767_571_200.0, 7 * 86400.0
    with history.session():
        for robot in range(3):
            for k in range(6):
                scale = 1.3 if robot == 1 and k == 5 else 1.0
                model = NoiseModel.from_dict({'axes': {
                    'gyro_x': {'white_noise': 5.8e-4 * scale, 'bias_instability': 1.5e-4},
                    'accel_x': {'white_noise': 8.3e-4 * scale, 'bias_instability': 7e-4}}})
                start = t0 + k * week + robot * 3600.0
                samples = Samples(t=start + np.arange(n) / rate,
                                  data=simulate(model, n, rate, seed=100 * robot + k),
                                  axes=('gyro_x', 'accel_x'),
                                  topic=f'/robot{robot}/imu/data_raw', frame_id='imu_link')
                report = analysis_to_json(analyze_samples(samples, options), samples)
                history.record({'input': str(tmp / f'robot{robot}_week{k}.mcap'), 'ok': True,
                                'report': report}, (1000, utc(start + 60.0)))
    out = tmp / 'fleet'
    proc = run_command('fleet', db, '--out', out)
    assert proc.returncode == 0, proc.stderr
    return out


def test_fleet_page(browser, fleet_out):
    """index.html: flagged IMU first, its flag in words, every record with a source link."""
    report = json.loads((fleet_out / 'fleet.json').read_text())
    assert [e['imu_id'] for e in report['imus'] if e['flagged']] == ['robot1/imu_link']
    text = _check_page(browser, fleet_out / 'index.html')
    order = [text.index(f'robot{k}/imu_link') for k in range(3)]
    assert order[1] == min(order)  # the flagged IMU is listed first
    assert 'left its own history' in text
    for flag in report['flags']:
        assert flag['why'] in text
    page = browser.open_page((fleet_out / 'index.html').resolve().as_uri())
    try:
        sources = page.evaluate('[...document.querySelectorAll("td.path a")]'
                                '.map(a => decodeURIComponent(a.href))')
    finally:
        page.close()
    assert len(sources) == 18 and all(s.endswith('.mcap') for s in sources)
    expected = {f'robot{r}_week{k}.mcap' for r in range(3) for k in range(6)}
    assert {s.rsplit('/', 1)[1] for s in sources} == expected


@pytest.mark.slow
def test_discrepancy_page(browser, tmp_path):
    """report.html of discrepancy: gaps before and after, the effect found, the model."""
    from imu_allan.formats.samples import Samples as S
    rate, n = 100.0, 60_000
    base = {'white_noise': {'value': 1e-3}, 'bias_instability': {'value': 3e-4}}
    truth = NoiseModel({'gyro_x': {**base, 'rate_random_walk': {'value': 4e-4}},
                        'gyro_y': dict(base)}, rate)
    path = tmp_path / 'rrw.csv'
    write_csv(path, S(np.arange(n) / rate, simulate(truth, n, rate, seed=11),
                      ('gyro_x', 'gyro_y'), 'test'))
    out = tmp_path / 'disc'
    proc = run_command('discrepancy', path, '--sims', '2', '--out', out, timeout=300)
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / 'report.json').read_text())
    assert [s['effect'] for s in report['steps']] == ['rate_random_walk']
    text = _check_page(browser, out / 'report.html')
    for gap in report['gap'].values():
        assert fmt(gap['initial'], 3) in text and fmt(gap['final'], 3) in text
    assert 'gyro_x + rate random walk' in text
    value = report['steps'][0]['parameters']
    for entry in value.values():
        assert fmt(entry['value']) in text and all(fmt(c) in text for c in entry['ci'])
    for terms in report['final_model'].values():
        for v in terms.values():
            assert fmt(v) in text


def test_bad_input_writes_no_page(tmp_path):
    """A bad input: one line, exit 2, and no report.html (nor any other file) left behind."""
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,gyro_x\n0,1\n')
    out = tmp_path / 'report'
    proc = run_command('analyze', bad, '--out', out)
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert not out.exists()
    assert [p.name for p in tmp_path.iterdir()] == ['bad.csv']


def test_optional_report_blocks(browser, analysis_dir, tmp_path):
    """
    The blocks other options add to report.json (design.md section 6) are shown when present.

    The keys are added to a real report in the contract's shapes (values made up for the
    page, not measured); the page must render them, still clean in the browser.
    """
    folder = tmp_path / 'report'
    shutil.copytree(analysis_dir, folder)
    report = json.loads((folder / 'report.json').read_text())
    gx = report['axes']['gyro_x']
    gx['fit']['alternatives'] = [['white_noise', 'bias_instability'],
                                 ['white_noise', 'gauss_markov']]
    tau = gx['adev']['tau']
    gx['deviations'] = {'mdev': {'tau': tau, 'dev': gx['adev']['adev'],
                                 'ci_low': gx['adev']['ci_low'],
                                 'ci_high': gx['adev']['ci_high'], 'edf': gx['adev']['edf']}}
    report['verdict']['warmup_s'] = 840.0
    report['dynamic'] = {'window_s': 120.0, 'step_s': 30.0, 'false_alarm_rate_per_day': 0.1,
                         'changes': [{'axis': 'accel_y', 't_s': 512.5, 'what': 'white noise up',
                                      'ratio': 1.8}]}
    report['overbound'] = {'horizon_s': 60.0, 'factors': {'kalibr': {'gyroscope_noise_density':
                                                                     1.25}}}
    report['temperature'] = {'topic': '/imu/temperature', 'range_c': [21.5, 38.25],
                             'slopes': {'gyro_x': {'value': 2.5e-5, 'ci': [2.0e-5, 3.0e-5],
                                                   'unit': 'rad/s/degC'}}}
    write_analysis_page(folder, report)
    text = _check_page(browser, folder / 'report.html')
    assert 'cannot yet reject white noise + Gauss-Markov' in text
    assert 'gyro_x mdev' in text
    assert 'first 840 s (14 min) left out' in text
    assert '512.5' in text and 'white noise up' in text and 'accel_y' in text
    assert '1.25' in text and 'gyroscope noise density' in text
    assert '21.5 to 38.25 °C' in text and '2.5e-05' in text
