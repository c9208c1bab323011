"""
The ``--out DIR`` files: report.json, Kalibr imu.yaml, allan_results.csv, plots, report.html.

report.html (:mod:`imu_allan.report.html`) shows the others; it is written last.

Files are first written into a staging folder next to DIR and moved in only when all of them
succeeded, so a failed run never leaves a half-written report behind.
"""

import csv
import json
import math
import os
from pathlib import Path
import shutil
import tempfile

from . import plots
from .json_report import analysis_to_json
from .kalibr import write_kalibr_yaml
from ..core.units import AXES, IEEE_TERMS, si_unit
from ..errors import InputError


def write_results_csv(path, analysis, denoised=None):
    """Thesis layout: one row per term, one column per axis (+ intervals, + denoised)."""
    axes = [a for a in AXES if a in analysis.axes]
    header = ['term', 'unit_gyro', 'unit_accel'] + axes
    header += [f'{a}_ci_low' for a in axes] + [f'{a}_ci_high' for a in axes]
    if denoised is not None:
        header += [f'{a}_denoised' for a in axes]
    fit = analysis.fit
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream)
        writer.writerow(header)
        for term in IEEE_TERMS:
            row = [term, si_unit('gyro_x', term), si_unit('accel_x', term)]
            row += [_cell(fit.value(a, term)) for a in axes]
            row += [_cell(fit.interval(a, term)[0]) for a in axes]
            row += [_cell(fit.interval(a, term)[1]) for a in axes]
            if denoised is not None:
                row += [_cell(denoised.fit.value(a, term)) for a in axes]
            writer.writerow(row)


def _cell(value):
    return f'{value:.6e}' if math.isfinite(value) else ''


def write_out_dir(out_dir, analysis, raw, denoised=None, report=None, topic='/imu/data_raw',
                  extra=None, exports=None):
    """
    Write every report file into ``out_dir`` atomically; returns the list of file names.

    ``extra(staging_dir)`` may write more files (e.g. a bag) into the staging folder first;
    ``exports = (names, inflate[, overbound, horizon_s])`` writes those exporters' files into
    ``export/`` (with ``overbound``, ``report.json`` gets their ``overbound`` block).
    """
    out_dir = Path(out_dir)
    try:
        return _write_out_dir(out_dir, analysis, raw, denoised, report, topic, extra, exports)
    except OSError as exc:  # name the user's folder, not the staging folder beside it
        raise InputError(out_dir, f'cannot write the report ({exc.strerror or exc})') from None


def _write_out_dir(out_dir, analysis, raw, denoised, report, topic, extra, exports):
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f'.{out_dir.name}.', dir=out_dir.parent))
    try:
        if extra is not None:
            extra(staging)
        report = report if report is not None else analysis_to_json(analysis)
        if exports and exports[0]:
            from .exporters import write_exports
            overbound = {}
            write_exports(staging, analysis, exports[0], inflate=exports[1], topic=topic,
                          overbound=bool(exports[2:3] and exports[2]),
                          horizon_s=exports[3] if len(exports) > 3 else None, summary=overbound)
            if overbound:
                report['overbound'] = overbound
        (staging / 'report.json').write_text(json.dumps(report, indent=1), encoding='utf-8')
        write_kalibr_yaml(staging / 'imu.yaml', analysis, topic)
        write_results_csv(staging / 'allan_results.csv', analysis, denoised)
        figures = {sensor: plots.plot_adev(staging / f'adev_{sensor}.png', analysis, sensor,
                                           denoised) for sensor in ('gyro', 'accel')}
        plots.plot_timeseries(staging / 'timeseries.png', analysis, raw)
        from .html import write_analysis_page  # last: it lists and shows the files above
        write_analysis_page(staging, report, figures)
        out_dir.mkdir(exist_ok=True)
        names = sorted(os.listdir(staging))
        for name in names:
            target = out_dir / name
            if target.is_dir():  # a bag folder from an earlier run: replaced whole
                shutil.rmtree(target)
            os.replace(staging / name, target)
        return names
    finally:
        shutil.rmtree(staging, ignore_errors=True)
