"""What every command shares: one-line errors with exit status 2, never a traceback."""

import argparse
import functools
import math
import os
import sys

from ..core.model import ModelError
from ..errors import InputError

EXIT_BAD_INPUT = 2


class ArgumentParser(argparse.ArgumentParser):
    """
    argparse with a one-line error (``prog: error: ...``), exit status 2, no abbreviations.

    Prefix matching is off: with it, ``--export all`` was silently taken as
    ``--export-samples all`` (a 200 MB CSV named ``all``).
    """

    def __init__(self, *args, **kwargs):
        """Build the parser (``allow_abbrev`` is always False)."""
        kwargs['allow_abbrev'] = False
        super().__init__(*args, **kwargs)

    def error(self, message):
        """Print one line and exit 2 (argparse prints the usage too, which we leave out)."""
        sys.stderr.write(f'{self.prog}: error: {message}\n')
        sys.exit(EXIT_BAD_INPUT)


def bounded_float(low, high, low_open=False):
    """
    Argparse ``type=``: a finite float in [low, high] (or (low, high]), else a usage error.

    Every numeric option of every command goes through this or :func:`bounded_int`, so
    ``--rate inf`` or ``--points-per-decade 100000`` is one line and exit 2, not a traceback
    or an hour of work.
    """
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
        if not math.isfinite(value) or value < low or value > high or (low_open and
                                                                       value == low):
            bound = f'> {low:g}' if low_open else f'>= {low:g}'
            raise argparse.ArgumentTypeError(f'{text} is out of range (must be {bound} and '
                                             f'<= {high:g})')
        return value
    parse.__name__ = 'number'
    return parse


def bounded_int(low, high):
    """Argparse ``type=``: an integer in [low, high], else a usage error (exit 2)."""
    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f'{text} is out of range ({low} to {high})')
        return value
    parse.__name__ = 'integer'
    return parse


def emit(text):
    """Print the result on stdout; a closed or failing stdout is an error, not a lost result."""
    try:
        if sys.stdout is None:  # started with stdout closed (``>&-``)
            raise OSError(9, 'standard output is closed')
        sys.stdout.write(text + '\n')
        sys.stdout.flush()
    except OSError as exc:
        raise InputError('stdout', f'cannot write the result ({exc.strerror or exc})') from None


def check_out_dir(path):
    """Refuse an ``--out DIR`` that cannot be written, before any work is done."""
    target = os.path.abspath(path)
    if os.path.exists(target):
        if not os.path.isdir(target):
            raise InputError(path, 'exists and is not a folder (--out needs a folder)')
    else:
        target = os.path.dirname(target)
        while not os.path.exists(target):
            target = os.path.dirname(target)
        if not os.path.isdir(target):
            raise InputError(path, f'{target} is not a folder')
    if not os.access(target, os.W_OK | os.X_OK):
        raise InputError(path, f'cannot write into {target} (permission denied)')


def guarded(main):
    """Run a command's main so bad input becomes one stderr line and exit status 2."""
    @functools.wraps(main)
    def wrapper(argv=None):
        prog = getattr(main, 'prog', main.__module__.rsplit('.', 1)[-1])
        try:
            return main(argv)
        except (InputError, ModelError) as exc:
            sys.stderr.write(f'{prog}: {exc}\n')
        except OSError as exc:
            where = exc.filename or 'output'
            sys.stderr.write(f'{prog}: {where}: {exc.strerror or exc}\n')
        except KeyboardInterrupt:
            sys.stderr.write(f'{prog}: interrupted\n')
            return 130
        return EXIT_BAD_INPUT
    return wrapper
