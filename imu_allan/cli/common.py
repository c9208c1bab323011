"""What every command shares: one-line errors with exit status 2, never a traceback."""

import argparse
import functools
import sys

from ..core.model import ModelError
from ..errors import InputError

EXIT_BAD_INPUT = 2


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (``prog: error: ...``), exit status 2, no abbreviations.

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
