"""``analyze``: IMU noise report from bags, logs, CSV and raw captures.

Usage: ``analyze INPUT... [--topic T] [--format auto|rosbag2|ros1|csv|thesis|gx3raw]
[--out DIR] [--json] [--export-samples FILE.csv] [--denoise]`` (docs/interfaces.md).
Several inputs are analysed in parallel, one process per core, and summarised in one table.
"""

from concurrent.futures import ProcessPoolExecutor
import json
import os
from pathlib import Path
import sys

from ..core.units import ALL_TERMS, IEEE_TERMS
from ..errors import InputError
from ..formats import FORMATS
from ..report.exporters import add_arguments as add_export_arguments
from .common import (
    ArgumentParser,
    bounded_float,
    bounded_int,
    check_out_dir,
    emit,
    EXIT_BAD_INPUT,
    guarded,
)
from .progress import Progress


def build_parser():
    """The command-line interface (contract options first)."""
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
    p.add_argument('--replace-outliers', action='store_true',
                   help='replace Tukey F=3 outliers by the axis mean (as the thesis did)')
    p.add_argument('--allow-jumps', action='store_true',
                   help='accept time-stamp jumps (treat the record as contiguous)')
    p.add_argument('--online', action='store_true',
                   help='use the bounded-memory online estimator of the allan node')
    p.add_argument('--jobs', type=bounded_int(0, 256), default=0,
                   help='parallel processes for several inputs (default: cores)')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    add_export_arguments(p)
    p.add_argument('--target', metavar='TERM=REL,...', default='',
                   help='precision targets of the recording advice: relative 68.3 %% '
                        'half-width per term, e.g. bias_instability=0.05 (default '
                        'white_noise=0.02, bias_instability=0.10, other terms 0.25)')
    return p


def _options(args):
    terms = None
    if args.terms:
        terms = [t.strip() for t in args.terms.split(',') if t.strip()]
    if args.export and not args.out:
        raise InputError('--export', 'needs --out DIR (the files go into DIR/export/)')
    from ..core.analysis import AnalysisOptions
    for term in terms or []:
        if term not in ALL_TERMS:
            raise InputError('--terms', f'unknown term {term!r} (known: {", ".join(ALL_TERMS)})')
    from ..core.advisor import parse_targets
    args.targets = parse_targets(args.target, '--target')
    return AnalysisOptions(terms=terms, points_per_decade=args.points_per_decade,
                           min_clusters=args.min_clusters, replace_outliers=args.replace_outliers,
                           tau_max=args.tau_max, rate_hz=args.rate, allow_jumps=args.allow_jumps,
                           online=args.online)


def _denoised_analysis(samples, analysis, options):
    from ..core.analysis import analyze_samples
    from ..core.denoise import denoise
    from ..formats.samples import Samples
    clean = denoise(analysis.data, analysis.rate_hz)
    den = Samples(t=samples.t, data=clean, axes=samples.axes,
                  source=samples.source + ' (denoised)')
    return den, analyze_samples(den, options)


def _write_denoised_bag(path, fmt, samples, denoised_samples, folder):
    """rosbag2 (MCAP) ``folder/denoised_bag`` with imu/data_denoised beside the original topics."""
    from ..formats.bag_writer import copy_bag_with_topic, write_imu_bag
    dst = Path(folder) / 'denoised_bag'
    if fmt in ('rosbag2', 'ros1'):
        copy_bag_with_topic(path, dst, 'imu/data_denoised', denoised_samples)
    else:
        write_imu_bag(dst, samples, topic='imu/data_raw', storage='mcap',
                      extra_topics={'imu/data_denoised': denoised_samples})
    return dst


def run_one(path, args, options, progress=None):
    """Analyse one input; return ``(report dict, console text)``; raise InputError."""
    from ..core.analysis import analyze_samples
    from ..formats.readers import read_samples
    from ..report.json_report import analysis_to_json, console_summary
    step = progress.step if progress else (lambda _name: None)
    step('reading')
    fmt = args.format
    samples = read_samples(path, fmt=fmt, topic=args.topic)
    if args.export_samples:
        from ..formats.csv_samples import write_csv
        write_csv(args.export_samples, samples)
    step('Allan deviation and fit')
    analysis = analyze_samples(samples, options)
    denoised = None
    report = analysis_to_json(analysis)
    from ..report.advice import advice_sentence, advice_to_json, compute_advice
    advice = compute_advice(analysis, options, args.targets)
    report['advice'] = advice_to_json(advice)
    if args.denoise:
        step('denoising')
        den_samples, denoised = _denoised_analysis(samples, analysis, options)
        report['denoised'] = {
            a: {'terms': denoised.fit.term_report(a),
                'adev': {'tau': denoised.result.tau.tolist(),
                         'adev': denoised.result.adev[:, j].tolist()}}
            for j, a in enumerate(denoised.axes)}
    if args.out:
        step('writing report')
        from ..report.outputs import write_out_dir
        out_dir = Path(args.out)
        if len(args.inputs) > 1:
            out_dir = out_dir / Path(str(path).rstrip('/')).name.replace('.', '_')
        extra = None
        if args.denoise:
            from ..formats.readers import detect_format
            real_fmt = detect_format(path) if fmt == 'auto' else fmt
            report['denoised_bag'] = str(out_dir / 'denoised_bag')

            def extra(staging):
                _write_denoised_bag(path, real_fmt, samples, den_samples, staging)
        report['out_files'] = write_out_dir(out_dir, analysis, samples.data, denoised, report,
                                            extra=extra, exports=(args.export, args.inflate))
    return report, console_summary(analysis) + '\n' + advice_sentence(advice)


def _worker(job):
    path, args, options = job
    try:
        return True, run_one(path, args, options)
    except InputError as exc:
        return False, str(exc)


def _summary_table(rows):
    head = (f'{"input":40} {"samples":>9} {"rate Hz":>8} {"hours":>6} {"static":>6} '
            f'{"gyro N worst (deg/sqrt(h))":>27} {"accel N worst (m/s/sqrt(h))":>28}')
    lines = ['summary:', head]
    for name, rep in rows:
        if isinstance(rep, str):
            lines.append(f'{name[-40:]:40} error: {rep}')
            continue
        kal = rep['kalibr']
        g = kal.get('gyroscope_noise_density')
        a = kal.get('accelerometer_noise_density')
        g_txt = f'{g * 60 * 57.29577951308232:.4g}' if g else '-'
        a_txt = f'{a * 60:.4g}' if a else '-'
        lines.append(f'{name[-40:]:40} {rep["n_samples"]:>9} {rep["sample_rate_hz"]:>8.4g} '
                     f'{rep["duration_s"] / 3600:>6.2f} {str(rep["verdict"]["static"]):>6} '
                     f'{g_txt:>27} {a_txt:>28}')
    return '\n'.join(lines)


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
    if len(args.inputs) == 1:
        steps = 2 + bool(args.denoise) + bool(args.out)  # read, estimate+fit, [denoise], [write]
        progress = Progress(args.inputs[0], steps, enabled=not quiet)
        try:
            report, text = run_one(args.inputs[0], args, options, progress)
        finally:
            progress.close()
        emit(json.dumps(report) if args.json else text)
        return 0
    jobs = args.jobs or os.cpu_count() or 1
    work = [(path, args, options) for path in args.inputs]
    progress = Progress('inputs', len(work), enabled=not quiet)
    with ProcessPoolExecutor(max_workers=min(jobs, len(work))) as pool:
        results = []
        for path, outcome in zip(args.inputs, pool.map(_worker, work)):
            progress.step(path)
            results.append((path, outcome))
    progress.close()
    failed = [(p, r) for p, (ok, r) in results if not ok]
    for _path, message in failed:
        sys.stderr.write(f'analyze: {message}\n')
    reports = [(p, r[0] if ok else r) for p, (ok, r) in results]
    if args.json:
        emit(json.dumps({'reports': [r for _, r in reports if not isinstance(r, str)],
                         'errors': [m for _, m in failed]}))
    else:
        for _path, (ok, rep) in results:
            if ok:
                print(rep[1] + '\n')
        print(_summary_table(reports))
    return EXIT_BAD_INPUT if failed else 0
