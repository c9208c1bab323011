"""
Analyse one input: read, estimate and fit, advice, denoise and ``--out`` files.

Used by ``analyze`` for a single input (:mod:`.analyze`) and by every task of a batch
(:mod:`.batch`, also on dask workers); both import it, it imports neither, so the dependency
points one way.
"""

from pathlib import Path


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


def run_one(path, args, options, progress=None, out_dir=None):
    """
    Analyse one input; return ``(report dict, console text)``; raise InputError.

    ``out_dir`` is where ``--out`` files go (default ``args.out``).
    """
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
    samples = analysis.samples  # without the isolated stamp faults the analysis dropped
    denoised = None
    report = analysis_to_json(analysis, samples)
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
    dynamic_text = ''
    if args.dynamic is not None:
        step('dynamic Allan deviation')
        from ..report.dynamic_plots import (
            analyze_dynamic,
            dynamic_json,
            dynamic_sentence,
            write_dynamic_plots,
        )
        dyn, changes = analyze_dynamic(analysis, args.dynamic)
        report['dynamic'] = dynamic_json(dyn, changes, analysis.warmup_s)
        dynamic_text = '\n' + dynamic_sentence(dyn, changes)
    from ..report.temperature_report import add_temperature, temperature_sentence
    add_temperature(report, path, fmt, samples, analysis)
    if args.out:
        step('writing report')
        from ..report.outputs import write_out_dir
        out_dir = Path(out_dir or args.out)
        extra = None
        if args.denoise:
            from ..formats.readers import detect_format
            real_fmt = detect_format(path) if fmt == 'auto' else fmt
            report['denoised_bag'] = str(out_dir / 'denoised_bag')

            def write_bag(staging):
                _write_denoised_bag(path, real_fmt, samples, den_samples, staging)
            extra = write_bag
        if args.dynamic is not None:
            extra = _also(extra, lambda staging: write_dynamic_plots(staging, dyn, changes))
        exports = (args.export, args.inflate, args.overbound, args.overbound_horizon)
        report['out_files'] = write_out_dir(out_dir, analysis, samples.data, denoised, report,
                                            extra=extra, exports=exports)
    return report, (console_summary(analysis) + '\n' + advice_sentence(advice)
                    + temperature_sentence(report) + dynamic_text)


def _also(first, then):
    """Return an ``extra`` writer that runs ``first`` (if any), then ``then``."""
    def both(staging):
        if first is not None:
            first(staging)
        then(staging)
    return both
