"""
The ``--out DIR`` files: report.json, Kalibr imu.yaml, allan_results.csv, plots, report.html.

All of them render one :class:`~imu_allan.core.record.RecordAnalysis`, computed before;
nothing here computes.  As asked with the record: the denoised bag, the dynamic plots and the
``export/`` files.  report.html (:mod:`imu_allan.report.html`) shows the others; it is
written last.

Files are first written into a staging folder next to DIR and moved in only when all of them
succeeded, so a failed run never leaves a half-written report behind.
"""

import csv
import math
import os
from pathlib import Path
import shutil
import tempfile

from . import plots, strict_json
from .json_report import OutFiles, record_to_json
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


def write_out_dir(out_dir, record, exports=None, input_path=None, input_format='auto',
                  topic='/imu/data_raw'):
    """
    Write every report file of a record's analysis into ``out_dir`` atomically.

    ``record``: a :class:`~imu_allan.core.record.RecordAnalysis`; ``exports``: an
    :class:`~.exporters.ExportOptions` (its files go into ``export/``; their ``overbound``
    block came with the record); ``input_path`` / ``input_format``: the input,
    which a denoised record's bag copies (a bag input) or holds beside the denoised topic.
    Returns the :class:`~.json_report.OutFiles` written (``files``: the names in ``out_dir``).
    """
    out_dir = Path(out_dir)
    try:
        return _write_out_dir(out_dir, record, exports, input_path, input_format, topic)
    except OSError as exc:  # name the user's folder, not the staging folder beside it
        raise InputError(out_dir, f'cannot write the report ({exc.strerror or exc})') from None


def _write_out_dir(out_dir, record, exports, input_path, input_format, topic):
    analysis, denoised = record.analysis, record.denoised
    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f'.{out_dir.name}.', dir=out_dir.parent))
    try:
        out = OutFiles()
        if denoised is not None:
            write_denoised_bag(staging, record, input_path, input_format)
            out.denoised_bag = str(out_dir / DENOISED_BAG)
        if record.dynamic is not None:
            from .dynamic_plots import write_dynamic_plots
            write_dynamic_plots(staging, record.dynamic)
        if exports is not None and exports.names:
            from .exporters import write_exports
            write_exports(staging, analysis, exports, topic=topic, fits=record.overbound)
        report = record_to_json(record, out)
        (staging / 'report.json').write_text(strict_json.dumps(report, indent=1), encoding='utf-8')
        write_kalibr_yaml(staging / 'imu.yaml', analysis, topic)
        den = denoised.analysis if denoised is not None else None
        write_results_csv(staging / 'allan_results.csv', analysis, den)
        figures = {sensor: plots.plot_adev(staging / f'adev_{sensor}.png', analysis, sensor,
                                           den) for sensor in ('gyro', 'accel')}
        plots.plot_timeseries(staging / 'timeseries.png', analysis)
        from .html import write_analysis_page  # last: it lists and shows the files above
        write_analysis_page(staging, report, figures)
        out_dir.mkdir(exist_ok=True)
        names = sorted(os.listdir(staging))
        for name in names:
            target = out_dir / name
            if target.is_dir():  # a bag folder from an earlier run: replaced whole
                shutil.rmtree(target)
            os.replace(staging / name, target)
        out.files = names
        return out
    finally:
        shutil.rmtree(staging, ignore_errors=True)


#: The folder of the denoised bag in ``--out DIR``.
DENOISED_BAG = 'denoised_bag'


def write_denoised_bag(folder, record, input_path=None, input_format='auto'):
    """
    rosbag2 (MCAP) ``folder/denoised_bag`` with imu/data_denoised beside the input's topics.

    A bag input is copied with the topic added; any other input (or none given) is written as
    imu/data_raw (the record read) beside imu/data_denoised.
    """
    from ..formats.bag_writer import copy_bag_with_topic, write_imu_bag
    dst = Path(folder) / DENOISED_BAG
    fmt = input_format
    if input_path is not None and fmt == 'auto':
        from ..formats.readers import detect_format
        fmt = detect_format(input_path)
    if input_path is not None and fmt in ('rosbag2', 'ros1'):
        copy_bag_with_topic(input_path, dst, 'imu/data_denoised', record.denoised.samples)
    else:
        write_imu_bag(dst, record.samples, topic='imu/data_raw', storage='mcap',
                      extra_topics={'imu/data_denoised': record.denoised.samples})
    return dst
