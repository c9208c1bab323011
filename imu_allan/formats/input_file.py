"""
Input files as the readers may use them: regular files and folders, nothing that blocks.

A FIFO (``analyze <(cat bag.mcap)``, a named pipe) is drained into a temporary file once a
writer appears, so every reader can seek and map it as usual; with no writer within
:data:`FIFO_WAIT_S` the read fails with a clear line instead of waiting forever. Character and
block devices and sockets (``/dev/zero``, ``/dev/ttyACM0``) are refused: they never end or are
not recordings (a live serial device is the driver's job).
"""

import atexit
import os
from pathlib import Path
import select
import shutil
import stat
import tempfile
import time

from ..errors import InputError

#: Seconds to wait for a FIFO's writer before giving up.
FIFO_WAIT_S = 10.0
#: Largest recording accepted through a FIFO (it is copied to a temporary file), bytes.
FIFO_MAX_BYTES = 64 << 30

_spooled = {}  # FIFO path -> temporary copy (one copy per process, removed at exit)


def _cleanup():
    for copy in _spooled.values():
        shutil.rmtree(copy.parent, ignore_errors=True)


atexit.register(_cleanup)


def regular_input(path, wait_s=None):
    """
    Return a path the readers can open: ``path`` itself, or a temporary copy of a FIFO.

    :class:`InputError` for a missing path, a device or socket, or a FIFO with no writer
    within ``wait_s`` seconds (default :data:`FIFO_WAIT_S`).
    """
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(path, 'no such file or directory') from None
    except OSError as err:
        raise InputError(path, f'cannot read: {err.strerror}') from None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return Path(path)
    if not stat.S_ISFIFO(mode):
        kind = 'a device' if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else 'a socket'
        raise InputError(path, f'{kind}, not a recording (give a file or a folder)')
    key = os.path.abspath(path)
    if key not in _spooled:
        _spooled[key] = _spool_fifo(path, FIFO_WAIT_S if wait_s is None else wait_s)
    return _spooled[key]


def _spool_fifo(path, wait_s):
    """Copy a FIFO's whole content into a temporary file; wait at most ``wait_s`` for data."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # opening for reading never blocks
    folder = Path(tempfile.mkdtemp(prefix='imu_allan_fifo_'))
    copy = folder / Path(path).name
    try:
        deadline = time.monotonic() + wait_s
        total = 0
        with open(copy, 'wb') as out:
            while True:
                remaining = deadline - time.monotonic() if total == 0 else None
                if remaining is not None and remaining <= 0:
                    raise InputError(path, f'a FIFO with no writer for {wait_s:g} s: nothing '
                                           'to read')
                ready, _, _ = select.select([fd], [], [], remaining)
                if not ready:
                    continue
                chunk = os.read(fd, 1 << 20)
                if not chunk:
                    if total == 0:
                        # No writer yet (EOF on an unconnected FIFO): poll until one opens.
                        time.sleep(0.05)
                        continue
                    break
                total += len(chunk)
                if total > FIFO_MAX_BYTES:
                    raise InputError(path, f'more than {FIFO_MAX_BYTES >> 30} GiB through the '
                                           'FIFO: give a file')
                out.write(chunk)
    except BaseException:
        shutil.rmtree(folder, ignore_errors=True)
        raise
    finally:
        os.close(fd)
    return copy
