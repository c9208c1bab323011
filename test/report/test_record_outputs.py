"""
The ``--out`` files and report.json render a computed record; writing computes nothing.

The record is generated here with numpy's generator (fixed seed), not the package's
simulator: 2 h at 20 Hz of white noise and a rate random walk, plus a bias settling
exp(-t / 300 s) at the start, which the warm-up detector leaves out.
"""

import json
import math

from imu_allan.core.analysis import AnalysisOptions
from imu_allan.core.record import analyze_record, RecordOptions
from imu_allan.formats.readers import read_samples
from imu_allan.formats.samples import Samples
from imu_allan.report.exporters import EXPORTERS, ExportOptions, write_exports
from imu_allan.report.json_report import OutFiles, record_text, record_to_json
from imu_allan.report.outputs import write_out_dir
import numpy as np
import pytest

RATE = 20.0
N = int(2 * 3600 * RATE)
EXPORTS = ExportOptions(names=tuple(EXPORTERS), inflate=(2.0, 3.0), overbound=True)


@pytest.fixture(scope='module')
def record():
    rng = np.random.default_rng(12)
    t = np.arange(N) / RATE
    data = (rng.standard_normal((N, 6)) * np.array([3e-4] * 3 + [2e-3] * 3) * math.sqrt(RATE)
            + np.cumsum(rng.standard_normal((N, 6)), axis=0)
            * np.array([2e-6] * 3 + [2e-5] * 3) / math.sqrt(RATE)
            + np.array([3e-3] * 3 + [3e-2] * 3) * np.exp(-t / 300.0)[:, None])
    data[:, 5] += 9.80665
    options = RecordOptions(analysis=AnalysisOptions(), dynamic_window_s=0.0, denoise=True,
                            overbound=EXPORTS.overbound_request())
    rec = analyze_record(Samples(t=1.7e9 + t, data=data, source='warm'), options)
    assert rec.analysis.warmup_s > 0  # the case this file is about
    return rec


def test_out_dir_computes_nothing_and_renders_the_record(record, tmp_path, monkeypatch):
    """
    With the overbound fit disabled, every file is still written: the fits came with the record.

    report.json is the printed report without ``out_files``; the export files equal those the
    Python API writes when it fits them itself.
    """
    from imu_allan.core import overbound

    reference = tmp_path / 'api'
    write_exports(reference, record.analysis, EXPORTS)

    def refuse(*_args, **_kwargs):
        raise AssertionError('an overbound was fitted while the files were written')
    monkeypatch.setattr(overbound, 'overbound_axes', refuse)
    out = write_out_dir(tmp_path / 'out', record, EXPORTS)
    assert 'report.json' in out.files and 'dynamic_gyro.png' in out.files
    assert 'denoised_bag' in out.files
    assert record.overbound.block['exports'].keys() == set(EXPORTERS)
    written = json.loads((tmp_path / 'out' / 'report.json').read_text())
    printed = json.loads(json.dumps(record_to_json(record, out)))
    assert printed.pop('out_files') == out.files
    assert written == printed
    keys = list(written)
    assert keys.index('advice') < keys.index('denoised') < keys.index('dynamic') \
        < keys.index('denoised_bag') < keys.index('overbound')
    for path in sorted((reference / 'export').iterdir()):
        assert (tmp_path / 'out' / 'export' / path.name).read_bytes() == path.read_bytes(), \
            path.name


def test_denoised_bag_holds_the_analysed_rows(record, tmp_path):
    """The denoised topic has the analysed stamps (after the warm-up), not the record's."""
    out = write_out_dir(tmp_path / 'out', record)
    assert out.denoised_bag == str(tmp_path / 'out' / 'denoised_bag')
    bag = tmp_path / 'out' / 'denoised_bag'
    den = read_samples(bag, topic='imu/data_denoised')
    raw = read_samples(bag, topic='imu/data_raw')
    assert den.n == record.analysis.n_samples < raw.n == N
    assert np.allclose(den.t, record.analysis.t, rtol=0, atol=1e-6)   # ns stamps
    assert np.allclose(den.data, record.denoised.samples.data, rtol=1e-6, atol=0)


def test_console_text_has_each_part_once(record):
    text = record_text(record)
    assert text.count('advice: ') == 1 and text.count('dynamic Allan deviation: ') == 1
    assert text.startswith('warm: ') and 'temperature (' not in text
    report = record_to_json(record, OutFiles())
    assert 'denoised_bag' not in report and report['overbound'] == record.overbound.block
    assert 'out_files' not in report and 'temperature' not in report
