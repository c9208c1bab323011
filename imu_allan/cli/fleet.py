"""
``fleet``: which IMU is getting worse?  Trends and flags from the ``analyze --db`` history.

Usage: ``fleet DB --out DIR [--json] [--since DATE]``.  Writes one trend plot per ``imu_id``
(``DIR/<imu_id>.png``), ``DIR/fleet.json`` and the page ``DIR/index.html``; prints a table of
the IMUs and one line per flag (``--json``: the JSON instead).  The flags are defined in
:mod:`imu_allan.history.trends`.
"""

from datetime import datetime
from pathlib import Path
import re

from .common import ArgumentParser, guarded
from ..errors import InputError
from ..report import strict_json


def build_parser():
    """Return the command-line interface."""
    p = ArgumentParser(
        prog='fleet',
        description='Per-IMU trends of white noise N and bias instability B (gyro and accel, '
                    'worst axis and per axis) from a DuckDB history written by analyze --db, '
                    "and flags: latest value outside its own history, or above the fleet's "
                    '95th percentile.')
    p.add_argument('db', metavar='DB', help='DuckDB file written by analyze --db')
    p.add_argument('--out', metavar='DIR', required=True,
                   help='write one PNG per IMU, fleet.json and index.html here')
    p.add_argument('--json', action='store_true', help='print the JSON report only')
    p.add_argument('--since', metavar='DATE',
                   help='only records that start on or after DATE (ISO 8601, UTC)')
    return p


def _since(text):
    if text is None:
        return None
    try:
        return datetime.fromisoformat(text).replace(tzinfo=None)
    except ValueError:
        raise InputError('--since', f'{text!r} is not an ISO 8601 date (YYYY-MM-DD)') from None


def _file_name(imu_id, used):
    base = re.sub(r'[^A-Za-z0-9_.-]+', '_', imu_id).strip('_.') or 'imu'
    name, k = base, 1
    while name in used:
        k += 1
        name = f'{base}_{k}'
    used.add(name)
    return name + '.png'


def _latest_worst(imu):
    out = {}
    for (sensor, term, axis), s in imu.series.items():
        if axis == 'worst' and s.value and (s.start[-1], s.inputs[-1]) == imu.records[-1]:
            out.setdefault(sensor, {})[term] = {'axis': s.axes[-1], 'value': s.value[-1],
                                                'ci': [s.low[-1], s.high[-1]], 'unit': s.unit}
    return out


def fleet_report(db, out_dir, since=None):
    """Load, flag and plot; return the JSON-ready report (also written to DIR/fleet.json)."""
    from ..history.db import connect
    from ..history.trends import analyse_fleet, load
    from ..report.fleet_plots import plot_imu
    with connect(db, read_only=True) as con:
        imus, moving = load(con, since)
    if not imus:
        when = f' since {since:%Y-%m-%d}' if since else ''
        raise InputError(db, f'no static measurements{when} (fill it with analyze --db)')
    flags = analyse_fleet(imus)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    used, entries = set(), []
    for imu_id in sorted(imus):
        imu = imus[imu_id]
        png = out / _file_name(imu_id, used)
        plot_imu(png, imu)
        entries.append({'imu_id': imu_id, 'records': len(imu.records),
                        'first_utc': imu.records[0][0].isoformat(),
                        'latest_utc': imu.records[-1][0].isoformat(),
                        'latest': _latest_worst(imu), 'flagged': bool(imu.flags),
                        'plot': str(png)})
    report = {'db': str(db), 'since': since.isoformat() if since else None,
              'units': 'SI; noise coefficients are continuous-time; intervals 68.3 %',
              'not_static_records_left_out': moving, 'imus': entries, 'flags': flags}
    (out / 'fleet.json').write_text(strict_json.dumps(report, indent=1) + '\n', encoding='utf-8')
    from ..report.html import write_fleet_page
    write_fleet_page(out, report, imus)
    return report


def _cell(latest, sensor, term):
    from ..core.units import conventional
    e = latest.get(sensor, {}).get(term)
    if e is None:
        return '-'
    return f'{conventional(e["axis"], term, e["value"])[0]:.3g}'


def console_text(report):
    """Return the table of IMUs and one line per flag."""
    head = (f'{"imu_id":28} {"records":>7} {"latest (UTC)":16} {"gyro N":>8} {"gyro B":>8} '
            f'{"accel N":>8} {"accel B":>8}  flags')
    lines = [f'fleet: {len(report["imus"])} IMUs from {report["db"]}'
             + (f' since {report["since"]}' if report['since'] else '')
             + f'; {report["not_static_records_left_out"]} non-static record(s) left out',
             'latest worst-axis values: N in deg/sqrt(h) (gyro), m/s/sqrt(h) (accel); '
             'B in deg/h, m/s/h', head]
    for e in report['imus']:
        n_flags = sum(f['imu_id'] == e['imu_id'] for f in report['flags'])
        lines.append(f'{e["imu_id"][-28:]:28} {e["records"]:>7} {e["latest_utc"][:16]:16} '
                     + ' '.join(f'{_cell(e["latest"], s, t):>8}' for s in ('gyro', 'accel')
                                for t in ('white_noise', 'bias_instability'))
                     + f'  {n_flags or ""}')
    lines.append(f'flags: {len(report["flags"])}')
    lines.extend('  ' + f['why'] for f in report['flags'])
    folder = Path(report['imus'][0]['plot']).parent
    lines.append(f'plots and fleet.json in {folder}; open {folder / "index.html"}')
    return '\n'.join(lines)


@guarded
def main(argv=None):
    """Entry point of ``fleet``."""
    args = build_parser().parse_args(argv)
    report = fleet_report(args.db, args.out, _since(args.since))
    print(strict_json.dumps(report) if args.json else console_text(report))
    return 0
