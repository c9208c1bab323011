r"""
Reader for the thesis text logs (the thesis, figure 4.2; docs/references.md).

Format: a few header lines, for example::

    Computed gyro bias (x;y;z): = 0.001043793745; 0.004222712480; -0.010834034532
        Data corresponds to accelerations(x;y;z); gyro rates(x;y;z); time stamp
        Time stamp are nanoseconds from 1st Jan 1970
        Acceleration vector needs to be scaled by gravity modulus at measure location: 9.80261

then one sample per line, ``;``-separated: acceleration x, y, z in g, gyro rates x, y, z in
rad/s, time stamp in ns since 1970. Accelerations are scaled by the header's local gravity
(9.80665 m/s^2 when the header gives none). The thesis' own example holds damaged lines
(backslashes, braces, runaway repeated fields); such lines are counted and skipped with a
warning. A line with ``:`` instead of ``;`` between otherwise valid fields is read (its values
are intact) and counted in a warning. Output columns are in the package order (gyro, accel).
"""

import re

import numpy as np

from .samples import Samples
from ..core.units import AXES, STANDARD_GRAVITY
from ..errors import InputError

_NUM = r'[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?'
_INT = r'[-+]?\d+'


def _line_pattern(sep):
    field = rf'({_NUM})\s*{sep}\s*'
    return re.compile(r'^\s*' + field * 6 + rf'({_INT})\s*;?\s*$')


_DATA = _line_pattern(';')
_DATA_COLON = _line_pattern(':')
_GRAVITY = re.compile(r'gravity modulus at measure location\s*:?\s*(' + _NUM + ')', re.I)


_BLOCK = 20_000  # lines parsed per numpy call; a block with a damaged line is parsed line by line
_ROW = np.dtype([('v', '<f8', (6,)), ('ns', '<i8')])


def _parse_block_fast(block):
    """Parse a block of well-formed lines with numpy; None if any line is not."""
    body = [ln for ln in block if ln.strip()]
    if not body:
        return np.zeros((0, 6)), np.zeros(0, dtype=np.int64)
    try:
        rows = np.loadtxt(body, delimiter=';', dtype=_ROW, ndmin=1)
    except (ValueError, OverflowError):  # OverflowError: a stamp beyond int64 (damage)
        return None
    if not np.isfinite(rows['v']).all():
        return None  # 'nan' or 'inf' text: the line-by-line parser counts such lines as damaged
    return rows['v'], rows['ns']


def _parse_block_slow(block, first_lineno):
    """Parse a block line by line; return ((values, ns), bad line numbers, ':' lines)."""
    rows, bad, colon = [], [], 0
    for lineno, ln in enumerate(block, start=first_lineno):
        mt = _DATA.match(ln)
        if mt is None:
            mt = _DATA_COLON.match(ln)
            if mt is not None:
                colon += 1
        if mt is None or not -2**63 <= int(mt.group(7)) < 2**63:  # a stamp beyond int64
            if ln.strip():
                bad.append(lineno)
            continue
        rows.append(mt.groups())
    values = np.array([r[:6] for r in rows], dtype=np.float64).reshape(len(rows), 6)
    ns = np.array([int(r[6]) for r in rows], dtype=np.int64)
    return (values, ns), bad, colon


def looks_like_thesis_log(text):
    """Return True if a text sample (the start of a file) looks like a thesis log."""
    if _GRAVITY.search(text) or 'gyro rates(x;y;z)' in text:
        return True
    lines = [ln for ln in text.splitlines()[:50] if ln.strip()]
    return sum(1 for ln in lines if _DATA.match(ln)) >= max(1, len(lines) // 2)


def read_thesis_log(path):
    """
    Read a thesis-format log; :class:`InputError` if unreadable or without a valid data line.

    ``t`` in s since 1970 (from the ns stamps), ``data`` (n, 6) in AXES order: gyro rad/s,
    accel m/s^2 (g times the header's gravity); ``gravity`` the value used.
    """
    try:
        with open(path, encoding='utf-8', errors='replace') as f:
            text = f.read()
    except FileNotFoundError:
        raise InputError(path, 'no such file') from None
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    if not text.strip():
        raise InputError(path, 'empty file')
    lines = text.splitlines()
    first = next((i for i, ln in enumerate(lines) if _DATA.match(ln) or _DATA_COLON.match(ln)),
                 None)
    if first is None:
        raise InputError(path, 'no data line in the thesis log format '
                               '(ax;ay;az in g; gx;gy;gz in rad/s; time in ns)')
    header = '\n'.join(lines[:first])
    gravity = STANDARD_GRAVITY
    m = _GRAVITY.search(header)
    if m:
        gravity = float(m.group(1))
        if not 9.7 < gravity < 9.9:
            raise InputError(path, f'implausible local gravity {gravity} m/s^2 in the header')
    values, stamp_ns, bad_lines, colon = [], [], [], 0
    for start in range(first, len(lines), _BLOCK):
        block = lines[start:start + _BLOCK]
        parsed = _parse_block_fast(block)
        if parsed is None:
            parsed, bad, n_colon = _parse_block_slow(block, start + 1)
            bad_lines += bad
            colon += n_colon
        values.append(parsed[0])
        stamp_ns.append(parsed[1])
    values = np.concatenate(values)
    stamp_ns = np.concatenate(stamp_ns)
    sec = stamp_ns // 1_000_000_000
    t = sec.astype(np.float64) + (stamp_ns - sec * 1_000_000_000).astype(np.float64) * 1e-9
    data = np.empty((values.shape[0], 6))
    data[:, :3] = values[:, 3:6]
    data[:, 3:] = values[:, :3] * gravity
    warnings = []
    if bad_lines:
        shown = ', '.join(str(x) for x in bad_lines[:5])
        more = ', ...' if len(bad_lines) > 5 else ''
        warnings.append(f'{len(bad_lines)} malformed line(s) skipped (line {shown}{more})')
    if colon:
        warnings.append(f"{colon} line(s) with ':' instead of ';' between fields read anyway")
    return Samples(t=t, data=data, axes=AXES, source=str(path), gravity=gravity,
                   warnings=warnings)
