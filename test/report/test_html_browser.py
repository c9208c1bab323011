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
one the tests skip and say so.  One browser serves the module; the inputs are short simulated
recordings (fixed seeds), so the module takes about 30 s, most of it the analyses.
"""

import io
import json
import re

from conftest import run_command
from imu_allan import NoiseModel, simulate
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
from imu_allan.report.html import fmt
import matplotlib.image
import numpy as np
import pytest

from .chromium import Chromium, find_chromium

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


def _check_page(browser, path):
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
        assert images or boxes, 'a page without a figure'
        width = page.evaluate('document.documentElement.scrollWidth')
        assert width <= 1280, f'the page is {width} px wide: it scrolls sideways at 1280 px'
        pixels = matplotlib.image.imread(io.BytesIO(page.screenshot()), format='png')[..., :3]
        ink = np.mean(pixels.mean(axis=2) < 0.9)
        colours = np.unique((pixels * 255).astype(np.uint8).reshape(-1, 3), axis=0).shape[0]
        assert pixels.shape[1] == 1280 and pixels.shape[0] > 600
        # text, table rules and plots: several % ink, hundreds of colours (anti-aliased
        # curves in a dozen hues); a blank or unstyled-error page has a handful
        assert ink > 0.02 and colours > 200, (ink, colours)
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
