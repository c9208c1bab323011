"""
``discrepancy``: where do a noise model and a recording disagree, and which effect is missing.

Usage::

    discrepancy INPUT [--model MODEL.yaml|SDF | --terms white_noise,bias_instability]
                [--json] [--out DIR] [--topic T] [--format FMT] [--sims K] [--seed S]

Reads the recording through :func:`imu_allan.formats.readers.read_samples`, runs the workflow of
:mod:`imu_allan.core.discrepancy` and prints a summary (or the JSON report with ``--json``).
``--out DIR`` writes ``report.json``, ``final_model.yaml``, PNG plots (and ``corrected.sdf``
for a Gazebo / PX4 SDF model, :mod:`imu_allan.formats.gazebo_sdf`) and the page
``report.html``.  Bad input: one line
on stderr naming the file and the problem, exit status 2.
"""

import json
import os
import sys

from .common import ArgumentParser, bounded_int, guarded
from ..formats import FORMATS
from ..report.discrepancy_report import report_dict, summary_text, write_plots


def build_parser():
    """Command-line parser."""
    parser = ArgumentParser(
        prog='discrepancy',
        description='Find where a noise model and measured IMU data disagree (Allan '
                    'deviation), name the missing effect, add it and show the gap shrink.')
    parser.add_argument('input', metavar='INPUT',
                        help='recording: rosbag2 folder/.db3/.mcap, ROS 1 .bag, CSV, thesis '
                             'log or raw 3DM-GX3-25 capture')
    start = parser.add_mutually_exclusive_group()
    start.add_argument('--model', metavar='MODEL',
                       help='starting noise model: a model YAML (SI units), or a Gazebo '
                            '<imu> SDF / world or PX4 gazebo_imu_plugin block (then --out '
                            'also writes corrected.sdf)')
    start.add_argument('--terms', metavar='T1,T2',
                       help='start from only these terms fitted to the data (default: '
                            'white_noise,bias_instability)')
    parser.add_argument('--json', action='store_true',
                        help='print the JSON report on stdout and nothing else')
    parser.add_argument('--out', metavar='DIR',
                        help='write report.json, final_model.yaml, PNG plots and '
                             'report.html to DIR')
    parser.add_argument('--topic', help='IMU topic in a bag (default: the only Imu topic)')
    parser.add_argument('--format', default='auto', choices=FORMATS,
                        help='input format (default: auto)')
    parser.add_argument('--sims', type=bounded_int(0, 1000), default=4, metavar='K',
                        help='simulated runs per model in the band (default 4)')
    parser.add_argument('--seed', type=bounded_int(0, 2**63 - 1), default=0,
                        help='simulation seed (default 0)')
    parser.add_argument('--max-steps', type=bounded_int(0, 20), default=4, metavar='N',
                        help='most effects added per axis (default 4)')
    return parser


def _fail(message):
    print(message, file=sys.stderr)
    return 2


@guarded
def main(argv=None):
    """Entry point; returns the exit status."""
    args = build_parser().parse_args(argv)
    from imu_allan.core.discrepancy import run_samples, sample_rate
    from imu_allan.core.model import ModelError, NoiseModel
    from imu_allan.errors import InputError

    if args.sims < 0 or args.max_steps < 0:
        return _fail('discrepancy: --sims and --max-steps must be >= 0')
    terms = None
    if args.terms is not None:
        terms = [t.strip() for t in args.terms.split(',') if t.strip()]
        if not terms:
            return _fail('--terms: give at least one term, e.g. white_noise,bias_instability')
    try:
        from imu_allan.formats import gazebo_sdf
        # a Gazebo <imu> / PX4 plugin SDF: read now, converted at the data's rate below
        sim = gazebo_sdf.read_sim_model(args.model) \
            if args.model and gazebo_sdf.looks_like_sdf(args.model) else None
        model = NoiseModel.from_yaml(args.model) if args.model and sim is None else None
        from imu_allan.formats.readers import read_samples
        samples = read_samples(args.input, args.format, args.topic)
        if samples.n < 20:
            raise InputError(args.input, f'only {samples.n} samples: too short')
        if sim is not None:
            model, sim_notes = sim.noise_model(sample_rate(samples.t))
        result = run_samples(samples, model=model, terms=terms, n_sims=args.sims,
                             seed=args.seed, max_steps=args.max_steps)
        if sim is not None:
            result.notes[:0] = sim_notes
    except (InputError, ModelError) as exc:
        return _fail(str(exc))
    except ValueError as exc:  # data the workflow cannot use (too short, no time stamps ...)
        return _fail(f'{args.input}: {exc}')
    except OSError as exc:
        return _fail(f'{args.input}: {exc.strerror or exc}')

    source = samples.source or args.input
    result.notes.extend(samples.warnings)
    from imu_allan.core.analysis import motion_verdict
    static, motion = motion_verdict(samples.data, samples.axes, result.measured.rate_hz)
    if not static:  # the same check as analyze: effects found on a moving IMU describe motion
        moving = ', '.join(a for a, d in motion.items() if d['moving'])
        result.notes.append(f'the IMU was not static ({moving} moved): the effects named '
                            f'describe the motion, not the sensor noise')
    report = report_dict(result, source)
    if args.out:
        try:
            os.makedirs(args.out, exist_ok=True)
            with open(os.path.join(args.out, 'report.json'), 'w', encoding='utf-8') as f:
                json.dump(report, f, indent=2)
            result.final_model.to_yaml(
                os.path.join(args.out, 'final_model.yaml'),
                header=f'discrepancy workflow result for {source}')
            write_plots(result, args.out)
            if sim is not None:  # the simulator's own file with the missing effects added
                with open(os.path.join(args.out, gazebo_sdf.CORRECTED_FILE), 'w',
                          encoding='utf-8') as f:
                    f.write(sim.corrected(result, source))
            from ..report.html import write_discrepancy_page
            write_discrepancy_page(args.out, report)  # last: it shows the files above
        except OSError as exc:
            return _fail(f'{args.out}: cannot write ({exc.strerror or exc})')
    try:
        if args.json:
            json.dump(report, sys.stdout, indent=2)
            sys.stdout.write('\n')
        else:
            print(summary_text(result, source))
            if args.out:
                print(f'report and plots written to {args.out}; open '
                      f'{os.path.join(args.out, "report.html")}')
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into head: not an error worth a traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == '__main__':
    sys.exit(main())
