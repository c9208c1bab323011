"""
``analyze``: IMU noise report from bags, logs, CSV and raw captures.

Usage: ``analyze INPUT... [--topic T] [--format auto|rosbag2|ros1|csv|thesis|gx3raw]
[--out DIR] [--json] [--export-samples FILE.csv] [--denoise]`` (docs/interfaces.md).
Several inputs (and folders, scanned for bags) are analysed as Dask tasks and summarised in
one table, optionally recorded in a DuckDB history (:mod:`imu_allan.cli.batch`).
"""

import sys

from .common import (
    ArgumentParser,
    bounded_float,
    bounded_int,
    check_out_dir,
    emit,
    guarded,
)
from .export_args import add_arguments as add_export_arguments
from .export_args import check_overbound_args, export_options
from .one_input import run_one
from .progress import Progress
from ..core.units import IEEE_TERMS, parse_terms
from ..errors import InputError
from ..formats import FORMATS
from ..report import strict_json


def build_parser():
    """Return the command-line interface (contract options first)."""
    p = ArgumentParser(
        prog='analyze',
        description='Allan-deviation noise analysis of a static IMU recording: overlapping '
                    'ADEV with 68.3 %% intervals, fitted IEEE noise terms (continuous-time, '
                    'SI units with conventional units beside them), a Kalibr imu.yaml and '
                    'plots.')
    p.add_argument('inputs', nargs='+', metavar='INPUT',
                   help='rosbag2 folder/.db3/.mcap, ROS 1 .bag, CSV, thesis log or raw capture')
    p.add_argument('--topic', help='sensor_msgs/Imu topic of a bag (default: the only one)')
    p.add_argument('--format', default='auto', choices=FORMATS, help='input format')
    p.add_argument('--out', metavar='DIR', help='write report.json, imu.yaml, '
                   'allan_results.csv and PNG plots here (one sub-folder per input when '
                   'several)')
    p.add_argument('--json', action='store_true', help='print the JSON report only')
    p.add_argument('--export-samples', metavar='FILE.csv',
                   help='write the decoded samples (before any filtering) as CSV')
    p.add_argument('--denoise', action='store_true',
                   help='also analyse the wavelet-denoised samples and, with --out, write a '
                        'rosbag2 (MCAP) with imu/data_denoised')
    p.add_argument('--terms', help='comma-separated terms to fit (default: selected by BIC '
                   f'among {", ".join(IEEE_TERMS)}); gauss_markov and sinusoid allowed')
    p.add_argument('--rate', type=bounded_float(0.0, 1e6, low_open=True), metavar='HZ',
                   help='sample rate (default: from the time stamps)')
    p.add_argument('--points-per-decade', type=bounded_float(1.0, 100.0), default=10.0,
                   help='averaging times per decade (default 10)')
    p.add_argument('--min-clusters', type=bounded_int(2, 10**6), default=10,
                   help='fewest clusters at the longest averaging time (default 10: T/10)')
    p.add_argument('--tau-max', type=bounded_float(0.0, 1e9, low_open=True), metavar='S',
                   help='longest averaging time, s')
    p.add_argument('--tau-range', metavar='LO,HI',
                   help='fit only these averaging times, s (default: chosen from the data, '
                        "where the sensor's own processing does not shape the curve)")
    p.add_argument('--plain-fit', action='store_true',
                   help='fit the IEEE terms over every averaging time, without measuring the '
                        "sensor's processing (its filter, lines and resonances)")
    p.add_argument('--replace-outliers', action='store_true',
                   help='replace Tukey F=3 outliers by the axis mean (as the thesis did)')
    p.add_argument('--allow-jumps', action='store_true',
                   help='accept time-stamp jumps (treat the record as contiguous)')
    p.add_argument('--allow-motion', action='store_true',
                   help='export the coefficients (Kalibr, --export) even when the IMU moved')
    p.add_argument('--online', action='store_true',
                   help='use the bounded-memory online estimator of the allan node')
    p.add_argument('--scheduler', metavar='tcp://HOST:PORT',
                   help='run on this dask.distributed scheduler (its workers must see the '
                        'input paths) instead of a local cluster')
    p.add_argument('--workers', type=bounded_int(0, 256), default=0, metavar='N',
                   help='worker processes of the local cluster (default: cores)')
    p.add_argument('--db', metavar='FILE',
                   help='append the results to this DuckDB history (created if absent)')
    p.add_argument('--force', action='store_true',
                   help='with --db: analyse inputs already recorded with the same size and '
                        'mtime again')
    p.add_argument('--imu-id', metavar='ID',
                   help='with --db: the imu_id of every input (default: the topic namespace '
                        'and the Imu frame_id)')
    p.add_argument('--estimators', default='oadev', metavar='KIND,...',
                   help='deviations to compute, comma-separated (default: oadev; also adev, '
                        'mdev, tdev, hdev, ohdev, totdev, mtotdev, htotdev, theo1): the '
                        'others go into report.json and onto the plots')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    p.add_argument('--dynamic', nargs='?', const=0.0, default=None, metavar='WINDOW_S',
                   type=bounded_float(0.0, 1e7),
                   help='dynamic Allan deviation over sliding windows and a change test per '
                        'axis (default window: the record / 24 in [60 s, 1 h]); with --out '
                        'also dynamic_gyro.png and dynamic_accel.png')
    add_export_arguments(p)
    p.add_argument('--target', metavar='TERM=REL,...', default='',
                   help='precision targets of the recording advice: relative 68.3 %% '
                        'half-width per term, e.g. bias_instability=0.05 (default '
                        'white_noise=0.02, bias_instability=0.10, other terms 0.25)')
    return p


def _options(args):
    """Return the :class:`~imu_allan.core.record.RecordOptions` of parsed arguments."""
    terms = parse_terms(args.terms or '', '--terms')
    if args.export and not args.out:
        raise InputError('--export', 'needs --out DIR (the files go into DIR/export/)')
    check_overbound_args(args)
    from ..core.analysis import AnalysisOptions
    from ..core.fit.advisor import parse_targets
    targets = parse_targets(args.target, '--target')
    from ..core.deviations import parse_kinds
    from ..core.record import RecordOptions
    analysis = AnalysisOptions(terms=terms, points_per_decade=args.points_per_decade,
                               min_clusters=args.min_clusters,
                               replace_outliers=args.replace_outliers, tau_max=args.tau_max,
                               rate_hz=args.rate, allow_jumps=args.allow_jumps,
                               online=args.online, allow_motion=args.allow_motion,
                               estimators=parse_kinds(args.estimators, '--estimators'),
                               sensor=not args.plain_fit, tau_range=_tau_range(args.tau_range))
    return RecordOptions(analysis=analysis, targets=targets, dynamic_window_s=args.dynamic,
                         denoise=args.denoise,
                         overbound=export_options(args).overbound_request())


def _tau_range(text):
    """``(lo, hi)`` s from ``--tau-range LO,HI`` (None when not given); InputError if bad."""
    if text is None:
        return None
    try:
        lo, hi = (float(v) for v in text.split(','))
    except ValueError:
        raise InputError('--tau-range', f'{text!r} is not LO,HI (two numbers, s)') from None
    if not (0.0 < lo < hi and hi < float('inf')):
        raise InputError('--tau-range', f'{text!r}: need 0 < LO < HI (s)')
    return lo, hi


@guarded
def main(argv=None):
    """Entry point of ``analyze``."""
    args = build_parser().parse_args(argv)
    options = _options(args)
    if args.export_samples and len(args.inputs) > 1:
        raise InputError('--export-samples', 'takes exactly one INPUT')
    if args.out:
        check_out_dir(args.out)
    quiet = args.quiet or args.json or not sys.stderr.isatty()
    from .batch import is_scan_folder, run_batch
    if len(args.inputs) == 1 and not (args.scheduler or args.db or
                                      is_scan_folder(args.inputs[0])):
        steps = 2 + bool(args.denoise) + bool(args.out) + (args.dynamic is not None)
        progress = Progress(args.inputs[0], steps, enabled=not quiet)
        try:
            report, text = run_one(args.inputs[0], args, options, progress)
        finally:
            progress.close()
        emit(strict_json.dumps(report) if args.json else text)
        return 0
    return run_batch(args, options)
