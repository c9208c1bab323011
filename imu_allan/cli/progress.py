"""A small progress bar on stderr (only on a terminal, never with --quiet or --json)."""

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
