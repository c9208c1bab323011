"""
The export options of ``analyze``: --export, --inflate, --overbound, --overbound-horizon.

Parsed into one :class:`~imu_allan.report.exporters.ExportOptions` (:func:`export_options`);
the exporters themselves and their registry are in :mod:`imu_allan.report.exporters`.
"""

import argparse
import math

from ..core.export_values import check_inflate
from ..errors import InputError
from ..report.exporters import exporter_names, EXPORTERS, ExportOptions


def parse_names(text, option='--export'):
    """``'kalibr,vins'`` or ``'all'`` -> list of names; InputError on an unknown name."""
    known = exporter_names()
    names = [n.strip() for n in str(text).split(',') if n.strip()]
    if not names:
        raise InputError(option, 'needs a comma-separated list of exporter names or "all"')
    if 'all' in names:
        return known
    unknown = [n for n in names if n not in EXPORTERS]
    if unknown:
        raise InputError(option, f'unknown exporter {", ".join(map(repr, unknown))} '
                                 f'(known: {", ".join(known)}, all)')
    return list(dict.fromkeys(names))


def parse_inflate(text, option='--inflate'):
    """``'2'`` or ``'2,10'`` -> ``(white, walk)``; InputError unless 0 < factor <= 1000."""
    parts = [p.strip() for p in str(text).split(',')]
    try:
        if len(parts) not in (1, 2):
            raise ValueError
        factors = [float(p) for p in parts]
    except ValueError:
        raise InputError(option, f'expected WHITE or WHITE,WALK (numbers), got {text!r}') from None
    try:
        return check_inflate(factors * 2 if len(factors) == 1 else factors)
    except ValueError as exc:
        raise InputError(option, str(exc)) from None


def parse_horizon(text, option='--overbound-horizon'):
    """``'20'`` -> 20.0 (s); InputError unless a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise InputError(option, f'expected a positive number of seconds, got {text!r}')
    return value


def check_overbound_args(args):
    """Refuse ``--overbound`` without ``--export`` and a horizon without ``--overbound``."""
    if args.overbound_horizon is not None and not args.overbound:
        raise InputError('--overbound-horizon', 'needs --overbound')
    if args.overbound and not args.export:
        raise InputError('--overbound', 'needs --export NAMES (it changes the exported values)')


def add_arguments(parser):
    """Add the ``--export`` and ``--inflate`` options of ``analyze`` (one-line errors, exit 2)."""
    def checked(parse):
        def convert(text):
            try:
                return parse(text)
            except InputError as exc:
                raise argparse.ArgumentTypeError(exc.problem) from None
        return convert
    parser.add_argument('--export', metavar='NAMES', type=checked(parse_names),
                        help='with --out: write consumer files into DIR/export/ (comma list '
                             f'of {", ".join(exporter_names())}, or all; docs/exports.md)')
    parser.add_argument('--inflate', metavar='WHITE[,WALK]', type=checked(parse_inflate),
                        default=(1.0, 1.0),
                        help='multiply the exported white-noise and bias standard deviations '
                             '(default 1: no inflation; 0 < factor <= 1000; with --overbound, '
                             'on top of it)')
    parser.add_argument('--overbound', action='store_true',
                        help="with --export: write the values of each consumer's own model "
                             'whose Allan variance is at or above the measured upper 95 %% bound '
                             'from tau0 to the horizon (docs/exports.md)')
    parser.add_argument('--overbound-horizon', metavar='S', type=checked(parse_horizon),
                        help='longest averaging time the overbound holds for, s (default: the '
                             'longest measured)')


def export_options(args):
    """Return the :class:`~imu_allan.report.exporters.ExportOptions` of parsed arguments."""
    return ExportOptions(names=tuple(args.export or ()), inflate=tuple(args.inflate),
                         overbound=bool(args.overbound), horizon_s=args.overbound_horizon)
