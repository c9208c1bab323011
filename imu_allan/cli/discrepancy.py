"""
``discrepancy``: where do a noise model and recordings disagree, and in what way.

Usage::

    discrepancy RECORDING... [--model MODEL.yaml|SDF | --terms white_noise,bias_instability]
                [--json] [--out DIR] [--topic T] [--format FMT] [--sims K] [--seed S]
                [--materiality LO,HI]

One recording: the single-recording workflow of :mod:`imu_allan.core.discrepancy` (the gap, the
missing effects added step by step) and, with ``--model``, the findings against the model as
stated.  Several recordings of one configuration (any rates, any number of runs; ``--model``
needed): the findings only (:func:`~imu_allan.core.discrepancy.find_discrepancies`).  A scale
factor is a finding only outside the ``--materiality`` band (default 0.8,1.25); inside it the
report says "consistent (within X %)".  A bag's
Imu covariance is read as the messages' own claim (:mod:`imu_allan.formats.imu_covariance`).
``--out DIR`` writes ``report.json``, ``report.html`` and, for one recording, the model, the
plots and ``corrected.sdf`` for a Gazebo / PX4 model, all at once (a staging folder moved in).
Bad input: one line on stderr naming the file and the problem, exit status 2.
"""

import os
import sys

from .common import ArgumentParser, bounded_int, check_out_dir, emit, EXIT_BAD_INPUT, guarded
from ..core.model import NoiseModel
from ..errors import InputError
from ..formats import FORMATS
from ..report import strict_json


def build_parser():
    """Command-line parser."""
    parser = ArgumentParser(
        prog='discrepancy',
        description='Find where a noise model and measured IMU data disagree (Allan '
                    'deviation): name the missing effect of one recording, and across '
                    'recordings at several rates and runs how each term is off.')
    parser.add_argument('inputs', nargs='+', metavar='RECORDING',
                        help='recording(s) of one configuration: rosbag2 folder/.db3/.mcap, '
                             'ROS 1 .bag, CSV, thesis log or raw 3DM-GX3-25 capture')
    start = parser.add_mutually_exclusive_group()
    start.add_argument('--model', metavar='MODEL',
                       help='the stated noise: a model YAML (SI units, continuous time, '
                            'turn_on_bias per sensor or axis), or a Gazebo <imu> SDF / world or '
                            'PX4 gazebo_imu_plugin block (then --out also writes corrected.sdf)')
    start.add_argument('--terms', metavar='T1,T2',
                       help='one recording: start from only these terms fitted to the data '
                            '(default: white_noise,bias_instability)')
    parser.add_argument('--json', action='store_true',
                        help='print the JSON report on stdout and nothing else')
    parser.add_argument('--out', metavar='DIR',
                        help='write report.json and report.html (one recording: also '
                             'final_model.yaml and PNG plots) to DIR')
    parser.add_argument('--topic', help='IMU topic in a bag (default: the only Imu topic)')
    parser.add_argument('--format', default='auto', choices=FORMATS,
                        help='input format (default: auto)')
    parser.add_argument('--sims', type=bounded_int(0, 1000), default=4, metavar='K',
                        help='simulated runs per model in the band (default 4)')
    parser.add_argument('--seed', type=bounded_int(0, 2**63 - 1), default=0,
                        help='simulation seed (default 0)')
    parser.add_argument('--max-steps', type=bounded_int(0, 20), default=4, metavar='N',
                        help='most effects added per axis (default 4)')
    parser.add_argument('--materiality', metavar='LO,HI',
                        help='scale factors (measured / stated) inside this band do not matter: '
                             'reported as consistent within X %%, not as findings (default '
                             '0.8,1.25, materiality.DEFAULT_BAND; 1,1: every significant factor)')
    return parser


def _materiality(text):
    """Return the ``--materiality LO,HI`` band (None: the default), or InputError."""
    from ..core.discrepancy.materiality import Materiality
    if text is None:
        return Materiality()
    try:
        lo, hi = (float(x) for x in text.split(','))
        return Materiality(lo, hi)
    except ValueError:
        raise InputError('--materiality', f'{text[:40]!r}: give LO,HI with 0 < LO <= 1 <= HI, '
                                          'e.g. 0.8,1.25') from None


def _read_model(path):
    """(NoiseModel as the file states it or None, SimImu or None) of ``--model``."""
    if path is None:
        return None, None
    from ..formats import gazebo_sdf
    if gazebo_sdf.looks_like_sdf(path):
        return None, gazebo_sdf.read_sim_model(path)
    return NoiseModel.from_yaml(path), None


def _read(path, args):
    """One recording: its samples, its rate and the covariance its messages state."""
    from ..core.discrepancy import sample_rate
    from ..formats.readers import read_samples
    samples = read_samples(path, args.format, args.topic)
    if samples.n < 20:
        raise InputError(path, f'only {samples.n} samples: too short')
    try:
        rate = sample_rate(samples.t)
    except ValueError as exc:
        raise InputError(path, str(exc)) from None
    stated, notes = {}, []
    if samples.topic:  # a bag: what do its messages say one sample's noise is?
        from ..formats.imu_covariance import read_covariance
        stated, notes = read_covariance(path, samples.topic)
    return samples, rate, stated, notes


def _moving(samples, rate_hz):
    """Return the axes that moved (the check analyze makes), or None for a static IMU."""
    from ..core.analysis import motion_verdict
    static, motion = motion_verdict(samples.data, samples.axes, rate_hz)
    return None if static else ', '.join(a for a, d in motion.items() if d['moving'])


def _one(args, model, sim, terms):
    """One recording: the single-recording workflow, plus findings against a stated model."""
    from ..core.discrepancy import find_discrepancies, Recording, run_discrepancy
    from ..report.discrepancy_report import report_dict, single_summary_text, write_plots
    path = args.inputs[0]
    samples, rate, stated, cov_notes = _read(path, args)
    start_model, sim_notes = sim.noise_model(rate) if sim is not None else (model, [])
    try:
        result = run_discrepancy(samples.data, rate, axes=samples.axes, model=start_model,
                                 terms=terms, n_sims=args.sims, seed=args.seed,
                                 max_steps=args.max_steps)
    except ValueError as exc:  # data the workflow cannot use (too short, constant ...)
        raise InputError(path, str(exc)) from None
    source = samples.source or path
    result.notes[:0] = sim_notes
    result.notes.extend(samples.warnings + cov_notes)
    moving = _moving(samples, result.measured.rate_hz)
    if moving:  # effects found on a moving IMU describe the motion
        result.notes.append(f'the IMU was not static ({moving} moved): the effects named '
                            f'describe the motion, not the sensor noise')
    findings = None
    if model is not None or sim is not None:
        # the stated model at this rate (a simulator file: its keys as documented), a note
        stated_model, note = sim.intended_model(rate) if sim is not None else (model, None)
        # the workflow's measured curve: the same data, rate, axes and averaging times
        findings = find_discrepancies([Recording(samples.data, rate, samples.axes, source,
                                                 stated, result.measured)], stated_model,
                                      materiality=args.band)
        if note:
            findings.notes.insert(0, note)
        if sim is not None:
            sim.suggest(findings.findings, [rate])
    report = report_dict(result, source, findings)
    if args.out:
        def files(folder):
            result.final_model.to_yaml(folder / 'final_model.yaml',
                                       header=f'discrepancy workflow result for {source}')
            write_plots(result, folder)
            if sim is not None:  # the simulator's own file with the missing effects added
                from ..formats.gazebo_sdf import CORRECTED_FILE
                (folder / CORRECTED_FILE).write_text(sim.corrected(result, source),
                                                     encoding='utf-8')
        _write(args.out, report, files)
    text = strict_json.dumps(report, indent=2) if args.json else single_summary_text(
        result, source, report)
    return text


def _several(args, model, sim):
    """
    Several recordings of one configuration: the findings against the stated model.

    A recording that cannot be read is left out, said in one stderr line and in the notes,
    and the command exits 2 after reporting on the others (as ``analyze`` does).
    Returns ``(text, errors)``.
    """
    from ..core.discrepancy import find_discrepancies, Recording
    from ..report.discrepancy_report import runs_report_dict, runs_summary_text
    recordings, models, notes, errors = [], [], [], []
    for path in args.inputs:
        try:
            samples, rate, stated, cov_notes = _read(path, args)
        except (InputError, OSError) as exc:
            errors.append(str(exc) if isinstance(exc, InputError) else
                          f'{path}: {exc.strerror or exc}')
            continue
        stated_model, note = sim.intended_model(rate) if sim is not None else (model, None)
        if note and note not in notes:
            notes.append(note)
        moving = _moving(samples, rate)
        notes += samples.warnings + cov_notes
        if moving:
            notes.append(f'{samples.source or path}: the IMU was not static ({moving} moved): '
                         f'what is found describes the motion, not the sensor noise')
        recordings.append(Recording(samples.data, rate, samples.axes,
                                    samples.source or path, stated))
        models.append(stated_model)
    if not recordings:
        raise InputError(args.inputs[0], errors[0].split(': ', 1)[-1])
    try:
        findings = find_discrepancies(recordings, models, materiality=args.band)
    except ValueError as exc:  # a record too short for any averaging-time grid
        raise InputError(args.inputs[0], str(exc)) from None
    if sim is not None:
        sim.suggest(findings.findings, [r.rate_hz for r in recordings])
    findings.notes[:0] = notes + [f'left out: {e}' for e in errors]
    report = runs_report_dict(findings, models[0], [r.source for r in recordings])
    if args.out:
        _write(args.out, report, lambda folder: None)
    text = strict_json.dumps(report, indent=2) if args.json else runs_summary_text(report)
    return text, errors


def _write(out, report, files):
    from ..report.discrepancy_report import write_out_dir
    try:
        write_out_dir(out, report, files)
    except OSError as exc:
        raise InputError(out, f'cannot write ({exc.strerror or exc})') from None


@guarded
def main(argv=None):
    """Entry point; returns the exit status."""
    args = build_parser().parse_args(argv)
    args.band = _materiality(args.materiality)
    terms = None
    if args.terms is not None:
        terms = [t.strip() for t in args.terms.split(',') if t.strip()]
        if not terms:
            raise InputError('--terms', 'give at least one term, e.g. '
                                        'white_noise,bias_instability')
    if len(args.inputs) > 1 and args.model is None:
        raise InputError('--model', f'{len(args.inputs)} recordings are compared with the '
                                    f'model they were made with: give --model')
    if args.out:
        check_out_dir(args.out)
    model, sim = _read_model(args.model)
    errors = []
    if len(args.inputs) == 1:
        text = _one(args, model, sim, terms)
    else:
        text, errors = _several(args, model, sim)
    emit(text)
    if args.out and not args.json:
        emit(f'report and plots written to {args.out}; open '
             f'{os.path.join(args.out, "report.html")}')
    for error in errors:
        sys.stderr.write(f'discrepancy: {error}\n')
    return EXIT_BAD_INPUT if errors else 0
