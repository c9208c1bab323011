"""
The CSV sample format of the contract (design page, section 5).

Header line ``t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z``: ``t`` in seconds, gyro in
rad/s, accel in m/s^2. ``t`` is required; any subset of the axis columns may be present (read
back in :data:`~imu_allan.core.units.AXES` order); extra columns (``mag_x``, ...) may follow the
axis columns and are returned in ``Samples.extra``. Blank lines and lines starting with ``#``
are ignored. Writing uses Python's shortest round-trip float repr, so write -> read gives the
same float64 values bit for bit.
"""

import contextlib
import os
import re
import tempfile

import numpy as np

from .samples import Samples
from ..core.units import AXES
from ..errors import InputError

_NAME = re.compile(r'^[A-Za-z_][A-Za-z0-9_.]*$')
_BLOCK = 100_000  # rows formatted per write call (bounds memory for long recordings)

#: Sample rates an IMU recording can have, Hz.  A ``t`` column whose median step gives a rate
#: below this range in seconds is in another unit: the one of ms, us, ns that lands in it.
IMU_RATE_HZ = (0.5, 50_000.0)
_TIME_UNITS = (('ms', 1e-3), ('us', 1e-6), ('ns', 1e-9))
_EPOCH_S = (1.0e9, 4.1e9)  # Unix time in s from 2001 to 2099: tells the unit of absolute stamps


def _time_scale(path, t):
    """
    Seconds per unit of the ``t`` column, and a warning when it is not 1 (s).

    The median step must give an IMU rate (:data:`IMU_RATE_HZ`).  If it does in seconds, t is
    seconds.  Otherwise the units ms, us, ns that do are candidates; absolute Unix stamps
    decide between several; one candidate is converted with a warning, none or several is an
    error that says why.
    """
    steps = np.diff(t)
    increasing = steps > 0
    if not increasing.all():
        steps = steps[increasing]
    if steps.size == 0:
        return 1.0, None
    step = float(np.median(steps, overwrite_input=True))  # steps is ours: no third copy
    low, high = IMU_RATE_HZ
    if 1.0 / step >= low:
        return 1.0, None
    fits = [(n, k) for n, k in _TIME_UNITS if low <= 1.0 / (step * k) <= high]
    epoch = [(n, k) for n, k in fits if _EPOCH_S[0] <= abs(t[0]) * k <= _EPOCH_S[1]]
    fits = epoch if len(epoch) == 1 else fits
    said = f'the t column steps by a median of {step:g}, which in seconds is {1.0 / step:.3g} Hz'
    if len(fits) == 1:
        name, scale = fits[0]
        return scale, (f'{said}: t read as {name} ({1.0 / (step * scale):.6g} Hz) and '
                       'converted to seconds')
    if not fits:
        raise InputError(path, f'{said}, and no unit (ms, us, ns) gives an IMU rate '
                               f'({low:g} to {high:g} Hz): write t in seconds')
    choices = ' or '.join(f'{n} ({1.0 / (step * k):.4g} Hz)' for n, k in fits)
    raise InputError(path, f'{said}: not seconds; {choices}? write t in seconds')


def _parse_header(path, line, lineno):
    names = [c.strip() for c in line.split(',')]
    seen = set()
    for name in names:
        if name in seen:
            raise InputError(path, f'line {lineno}: column {name!r} appears twice')
        seen.add(name)
    if 't' not in names:
        raise InputError(path, f'line {lineno}: no t column in the header '
                               '(expected t,gyro_x,...,accel_z)')
    axis_pos = [i for i, n in enumerate(names) if n in AXES]
    last_axis = max(axis_pos) if axis_pos else names.index('t')
    for i, name in enumerate(names):
        if name == 't' or name in AXES:
            continue
        looks_like_axis = name.lower().startswith(('gyro', 'accel', 'acc_', 'time'))
        if i < last_axis or looks_like_axis or not _NAME.match(name):
            raise InputError(path, f'line {lineno}: unknown column {name!r} (known: t, '
                                   f'{", ".join(AXES)}; extra columns only after the axes)')
    if not axis_pos:
        raise InputError(path, f'line {lineno}: no axis column ({", ".join(AXES)})')
    return names


def _locate_bad(path, lines, first, names):
    """Find the first bad data line of a block whose first line is ``first`` (for the error)."""
    k = len(names)
    for lineno, text in enumerate(lines, start=first):
        text = text.strip()
        if not text or text.startswith('#'):
            continue
        cells = text.split(',')
        if len(cells) != k:
            raise InputError(path, f'line {lineno}: {len(cells)} cells, the header has {k}')
        for name, cell in zip(names, cells):
            try:
                value = float(cell)
            except ValueError:
                raise InputError(path, f'line {lineno}, column {name}: not a number: '
                                       f'{cell.strip()[:40]!r}') from None
            if not np.isfinite(value):
                raise InputError(path, f'line {lineno}, column {name}: {cell.strip()} '
                                       '(NaN or infinite value)')
    raise InputError(path, 'unreadable numbers')  # pragma: no cover (loadtxt and float agree)


#: Lines parsed per numpy call: the text held in memory is one block, not the whole file.
_ROWS = 25_000
#: Longest line accepted: a sample line is under 200 characters; this bounds what one read takes
#: from a file with no line breaks.
MAX_LINE = 1 << 16


def _lines(path, f, lineno):
    """Yield ``(lineno, line)`` with a length limit on each line."""
    while True:
        line = f.readline(MAX_LINE + 1)
        if not line:
            return
        lineno += 1
        if len(line) > MAX_LINE:
            raise InputError(path, f'line {lineno}: longer than {MAX_LINE} characters: not a '
                                   'sample CSV')
        yield lineno, line


class _Columns:
    """
    The final arrays (t, data, extra columns) filled block by block: no concatenation.

    The row count is estimated from the file size and the first block's bytes per line, so
    the arrays are allocated once (grown by doubling if the estimate was short).
    """

    def __init__(self, names, file_bytes):
        self.axes = tuple(a for a in AXES if a in names)
        self.t_col = names.index('t')
        self.axis_cols = [names.index(a) for a in self.axes]
        self.extra_cols = {n: i for i, n in enumerate(names) if n != 't' and n not in AXES}
        self.file_bytes = file_bytes
        self.n = 0
        self.t = np.empty(0)
        self.data = np.empty((0, len(self.axes)))
        self.extra = {n: np.empty(0) for n in self.extra_cols}

    def add(self, table, block_bytes):
        """Append a parsed block (rows, columns) that came from ``block_bytes`` of text."""
        m = table.shape[0]
        if self.n + m > self.t.shape[0]:
            estimate = int(self.file_bytes * m / max(block_bytes, 1) * 1.02) + 1
            self._grow(max(self.n + m, 2 * self.t.shape[0], estimate))
        rows = slice(self.n, self.n + m)
        self.t[rows] = table[:, self.t_col]
        self.data[rows] = table[:, self.axis_cols]
        for name, i in self.extra_cols.items():
            self.extra[name][rows] = table[:, i]
        self.n += m

    def _grow(self, size):
        def grown(old):
            new = np.empty((size,) + old.shape[1:])
            new[:self.n] = old[:self.n]
            return new
        self.t, self.data = grown(self.t), grown(self.data)
        self.extra = {name: grown(col) for name, col in self.extra.items()}

    def arrays(self):
        """(t, data, extra) with exactly the rows read."""
        n = self.n
        return self.t[:n], self.data[:n], {name: col[:n] for name, col in self.extra.items()}


def _read_table(path, f):
    """Read header and rows in blocks of :data:`_ROWS` lines into :class:`_Columns`."""
    lines = _lines(path, f, 0)
    header_no, header = next(((n, ln) for n, ln in lines
                              if ln.strip() and not ln.lstrip().startswith('#')), (None, None))
    if header_no is None:
        raise InputError(path, 'empty file (no CSV header)')
    names = _parse_header(path, header.rstrip('\r\n'), header_no)
    columns = _Columns(names, os.fstat(f.fileno()).st_size)
    block, first = [], header_no + 1
    for lineno, line in lines:
        if not block:
            first = lineno
        block.append(line)
        if len(block) == _ROWS:
            columns.add(_parse_block(path, block, first, names), sum(map(len, block)))
            block = []
    if block:
        columns.add(_parse_block(path, block, first, names), sum(map(len, block)))
    return columns


def _parse_block(path, block, first, names):
    """One block of lines -> (rows, columns) float64; InputError naming the first bad line."""
    body = [ln for ln in block if ln.strip() and not ln.lstrip().startswith('#')]
    if not body:
        return np.zeros((0, len(names)))
    try:
        table = np.loadtxt(body, delimiter=',', dtype=np.float64, ndmin=2)
    except ValueError:
        table = None
    if table is None or table.shape[1] != len(names) or not np.isfinite(table).all():
        _locate_bad(path, block, first, names)
    return table


def read_csv(path):
    """
    Read a CSV sample file: ``t`` (s), ``data`` (n, A) SI, ``axes`` the axis columns present.

    ``extra``: the extra columns by name; a header with no rows gives n = 0.  Raises
    :class:`InputError` for a missing or empty file, no ``t`` column, unknown or duplicate
    columns, a wrong cell count, non-numeric cells (line and column named), NaN or infinite
    values (first line named).
    """
    try:
        with open(path, encoding='utf-8') as f:
            columns = _read_table(path, f)
    except FileNotFoundError:
        raise InputError(path, 'no such file') from None
    except UnicodeDecodeError:
        raise InputError(path, 'not a text file (CSV expected)') from None
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    t, data, extra = columns.arrays()
    scale, note = _time_scale(path, t)
    if note:
        t *= scale
    return Samples(t=t, data=data, axes=columns.axes, source=str(path), extra=extra,
                   warnings=[note] if note else [])


def write_csv(path, samples):
    """Write samples as CSV (header ``t,<axes>,<extra columns>``), exact float round trip."""
    t = np.asarray(samples.t, dtype=np.float64)
    data = np.asarray(samples.data, dtype=np.float64).reshape(t.shape[0], len(samples.axes))
    extra = dict(samples.extra or {})
    names = ['t', *samples.axes, *extra]
    columns = [t, *(data[:, j] for j in range(data.shape[1])),
               *(np.asarray(v, dtype=np.float64) for v in extra.values())]
    # Written beside the target and renamed into place: a full disk or an interruption never
    # leaves a half-written CSV under the user's name.
    folder = os.path.dirname(os.path.abspath(path))
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f'.{os.path.basename(path)}.', dir=folder)
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(fd, 0o666 & ~umask)  # the mode open() would give, not mkstemp's 0600
        with open(fd, 'w', encoding='utf-8', newline='\n') as f:
            f.write(','.join(names) + '\n')
            for start in range(0, t.shape[0], _BLOCK):
                # repr() is Python's shortest string that reads back to the same float64.
                cols = [list(map(repr, c[start:start + _BLOCK].tolist())) for c in columns]
                f.write('\n'.join(map(','.join, zip(*cols))))
                f.write('\n')
        os.replace(tmp, path)
        tmp = None
    except OSError as err:
        raise InputError(path, f'cannot write: {err.strerror or err}') from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
