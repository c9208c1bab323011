"""A small progress bar on stderr (only on a terminal, never with --quiet or --json)."""

from pathlib import Path
import sys
import time


class Progress:
    """``[#####.....] 3/6 stage`` redrawn in place on stderr."""

    def __init__(self, label, total, enabled=True, width=24):
        """Start a bar of ``total`` steps."""
        self.label, self.total, self.enabled, self.width = label, max(total, 1), enabled, width
        self.done = 0
        self.start = time.monotonic()

    def step(self, name):
        """Advance one step and show its name."""
        self.done = min(self.done + 1, self.total)
        if not self.enabled:
            return
        filled = int(self.width * self.done / self.total)
        bar = '#' * filled + '.' * (self.width - filled)
        elapsed = time.monotonic() - self.start
        sys.stderr.write(f'\r{self.label[-30:]} [{bar}] {self.done}/{self.total} {name[:40]:40}'
                         f' {elapsed:6.1f} s')
        sys.stderr.flush()

    def close(self):
        """End the bar's line."""
        if self.enabled and self.done:
            sys.stderr.write('\n')
            sys.stderr.flush()


class RunProgress(Progress):
    """
    One bar for a run of several inputs: done / total and failures so far.

    On a terminal it is the bar; elsewhere (a log, a pipe) one plain line per finished input.
    """

    def __init__(self, total, tty, enabled=True):
        """Start a run of ``total`` inputs; ``tty``: stderr is a terminal."""
        super().__init__('inputs', total, enabled=enabled and tty)
        self.plain = enabled and not tty
        self.failed = 0

    def finished(self, name, error=None):
        """Count one finished input (``error``: its reason if it failed, said at the end)."""
        self.failed += error is not None
        if self.plain:
            self.done = min(self.done + 1, self.total)
            sys.stderr.write(f'[{self.done}/{self.total}, {self.failed} failed] {name}: '
                             f'{"failed" if error else "ok"}\n')
            sys.stderr.flush()
        else:
            self.step(f'{self.failed} failed, last {Path(str(name).rstrip("/")).name}')
