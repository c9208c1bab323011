"""
The change test on a live stream: what the allan node runs (ROS-free).

:class:`ChangeMonitor` feeds header-stamped batches to a
:class:`~imu_allan.core.change.dynamic.BlockAllan` (fixed memory: per-block sums, never samples)
and its completed blocks to a :class:`~imu_allan.core.change.detection.ChangeTest`, the same test
``analyze --dynamic`` runs on a whole record.  Times are header stamps (s): a change's
``t_s`` is the stamp of the first sample of the block where it happened.

Per axis a diagnostic record ``<prefix><axis> change``: OK, or WARN once a change is
detected, with ``changed_at`` (stamp, s), ``ratio`` and ``what``.  The WARN stays until
:meth:`reset` (the node: any ``ros2 param set`` of ``change_reset``, or a new
``change_window_s``) or, when ``hold_s`` > 0, until the stream's stamps have passed
``hold_s`` seconds beyond the detection.  Samples are taken as evenly spaced (stamp gaps are
not filled); non-finite and non-physical values are missing data.
"""

import math

import numpy as np

from .health import Health, OK, WARN
from ..change.detection import ChangeTest
from ..change.dynamic import BlockAllan, BLOCKS_PER_WINDOW, layout
from ..units import physical_limits

#: Samples gathered before a feed (s of data): the block sums cost a few milliseconds per
#: call whatever its size (a few numpy calls per averaging factor), so the node's 50-ms drains
#: are batched (2 s at 1 kHz x 6 axes: 96 KiB held at most).
FEED_EVERY_S = 2.0


class ChangeMonitor:
    """
    Stream form of the change test, per axis, with its diagnostic records.

    ``rate_hz`` in Hz; ``window_s`` the window, s (step = window / 4); ``hold_s`` (stamp
    time, s) how long a WARN lasts after its detection (0: until :meth:`reset`);
    ``target_per_day`` the false alarms per axis per day the threshold aims at.
    """

    def __init__(self, rate_hz, window_s, axes, hold_s=0.0, target_per_day=None):
        self.rate_hz = float(rate_hz)
        self.window_s = float(window_s)
        self.axes = tuple(axes)
        self.hold_s = float(hold_s)
        self.target = target_per_day
        self._limits = np.asarray(physical_limits(self.axes))
        self.block, self.ms = layout(window_s, rate_hz)
        self._start()

    def _start(self):
        self.acc = BlockAllan(len(self.axes), self.block, self.ms)
        self.test = ChangeTest(self.rate_hz, self.block, self.ms, BLOCKS_PER_WINDOW, self.axes,
                               self.target)
        self._starts = []  # stamps of the blocks begun and not yet complete
        self._pending_t, self._pending_y = [], []
        self._n_pending = 0
        self.latest = {}  # axis -> the last Change (cleared on reset / hold)
        self.last_stamp = math.nan
        self.n_changes = 0

    def reset(self):
        """Forget the detections and every baseline: the test starts again from now."""
        self._start()

    @property
    def step_s(self):
        """Step (block) length, s."""
        return self.block / self.rate_hz

    def memory_bytes(self):
        """Bytes held (fixed; the pending batch is at most FEED_EVERY_S of samples)."""
        return self.acc.memory_bytes() + self.test.memory_bytes()

    def feed(self, t, data):
        """Add samples with stamps ``t`` (s, (n,)) and ``data`` (n, A) SI; return new changes."""
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return []
        self._pending_t.append(t)
        self._pending_y.append(np.asarray(data, dtype=float))
        self._n_pending += t.size
        if self._n_pending < FEED_EVERY_S * self.rate_hz:
            return []
        return self.flush()

    def flush(self):
        """Feed the gathered samples now; return the changes they complete."""
        if not self._n_pending:
            return []
        t = np.concatenate(self._pending_t)
        y = np.concatenate(self._pending_y)
        self._pending_t, self._pending_y, self._n_pending = [], [], 0
        with np.errstate(invalid='ignore'):
            y = np.where(np.abs(y) <= self._limits, y, np.nan)  # missing, not a spike
        n0 = self.acc.n_fed
        first = -(-n0 // self.block) * self.block
        self._starts += t[np.arange(first, n0 + t.size, self.block) - n0].tolist()
        blocks = self.acc.feed(y)
        starts = np.array(self._starts[:blocks.n])
        del self._starts[:blocks.n]
        self.last_stamp = float(t[-1])
        changes = self.test.push(blocks, starts)
        for c in changes:
            self.latest[c.axis] = c
        self.n_changes += len(changes)
        return changes

    def health(self, prefix=''):
        """One :class:`~imu_allan.core.live.health.Health` per axis: ``<prefix><axis> change``."""
        records = []
        for j, axis in enumerate(self.axes):
            change = self.latest.get(axis)
            if change is not None and self.hold_s > 0 and \
                    self.last_stamp - change.extra.get('reported_s', change.t_s) > self.hold_s:
                del self.latest[axis]  # held long enough
                change = None
            values = {'window_s': self.window_s, 'step_s': self.step_s,
                      'baseline_s': float(self.test.base_blocks[j]) * self.step_s,
                      'target_false_alarms_per_day': float(self.test.target),
                      'hold_s': self.hold_s}
            name = f'{prefix}{axis} change'
            if change is None:
                needed = self.test.baseline_blocks
                ready = self.test.base_blocks[j] >= needed
                message = ('no change against the baseline' if ready else
                           f'building the baseline ({values["baseline_s"]:.0f} of '
                           f'{needed * self.step_s:.0f} s)')
                records.append(Health(name, OK, message, values))
                continue
            # Stamps as text with ns digits (a float would be shown with 6 significant ones).
            values.update({'changed_at': f'{change.t_s:.9f}', 'ratio': float(change.ratio),
                           'what': change.what, 'detected_at': f'{change.detected_s:.9f}'})
            records.append(Health(name, WARN, f'{change.what} changed at stamp '
                                              f'{change.t_s:.3f} s (x{change.ratio:.3g})',
                                  values))
        return records
