"""
Analyse one input: read it once, analyse the record in one call, render what was asked.

Used by ``analyze`` for a single input (:mod:`.analyze`) and by every task of a batch
(:mod:`.batch`, also on dask workers); both import it, it imports neither, so the dependency
points one way.  The numbers are computed in :func:`imu_allan.core.record.analyze_record`;
the console text, report.json and the ``--out`` files only render its result.
"""

from pathlib import Path


def run_one(path, args, options, progress=None, out_dir=None):
    """
    Analyse one input; return ``(report dict, console text)``; raise InputError.

    ``options``: the :class:`~imu_allan.core.record.RecordOptions` (``analyze._options``);
    ``args`` chooses the input (``format``, ``topic``) and the outputs (``export_samples``,
    ``out``, the export options); ``out_dir`` is where ``--out`` files go (default
    ``args.out``).
    """
    from ..core.record import analyze_record
    from ..formats.readers import read_samples
    from ..report.json_report import record_text, record_to_json
    step = progress.step if progress else (lambda _name: None)
    step('reading')
    samples = read_samples(path, fmt=args.format, topic=args.topic, temperature=True)
    if args.export_samples:
        from ..formats.csv_samples import write_csv
        write_csv(args.export_samples, samples)
    record = analyze_record(samples, options, step)
    out = None
    if args.out:
        step('writing report')
        from .export_args import export_options
        from ..report.outputs import write_out_dir
        out = write_out_dir(Path(out_dir or args.out), record, export_options(args),
                            input_path=path, input_format=args.format)
    return record_to_json(record, out), record_text(record)
