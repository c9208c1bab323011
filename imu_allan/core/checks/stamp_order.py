"""
The one rule for out-of-order and repeated header stamps, offline and online.

A sample is kept when its stamp is later than every stamp kept before it (the running
maximum): a stamp that went backwards, or repeats the one before, is dropped and counted.
The allan node applies it batch by batch (:class:`~imu_allan.core.live.health.StampMonitor`, the
running maximum carried between batches) and ``analyze`` to the whole record
(:func:`drop_isolated`), so both drop the same samples.

Offline, dropping is only right for *isolated* faults, a damaged stamp here and there: a
record is refused when two dropped samples are neighbours (a stretch that runs backwards, or
a stamp far ahead that hides the samples after it) or when more than :data:`MAX_DROPPED_SHARE`
of its samples would be dropped (at least one is always allowed).
Online a stream cannot be refused: the node keeps dropping and reports the count in its
diagnostics.
"""

from dataclasses import replace
import math

import numpy as np

#: Largest share of a record's samples dropped as isolated stamp faults (1 in 1000); more
#: means the stamps themselves are wrong, not a few damaged messages.
MAX_DROPPED_SHARE = 1e-3

#: Samples named in the warning.
NAMED = 3


def keep_increasing(t, last=-math.inf):
    """
    Return the keep mask of stamps ``t`` (s, (n,)): later than every earlier kept stamp.

    ``last``: the last kept stamp before ``t`` (a stream's previous batches).  A NaN stamp
    is dropped and does not change the running maximum.
    """
    t = np.asarray(t, dtype=float)
    running = np.fmax.accumulate(np.concatenate(([last], t)))
    return t > running[:-1]


def drop_isolated(t):
    """
    Apply the rule to a whole record.

    Returns ``(keep, problem)``: ``keep`` the mask of samples kept (None when every stamp
    increases), and ``problem`` None when the dropped samples are isolated, else the words
    that say why the record is refused.
    """
    t = np.asarray(t, dtype=float)
    if t.size < 2 or bool(np.all(t[1:] > t[:-1])):
        return None, None
    keep = keep_increasing(t)
    dropped = ~keep
    n_dropped = int(dropped.sum())
    limit = max(1, int(MAX_DROPPED_SHARE * t.size))
    if n_dropped > limit:
        return keep, (f'{n_dropped} samples would be dropped, more than {limit} '
                      f'(1 in {round(1 / MAX_DROPPED_SHARE)})')
    pair = np.flatnonzero(dropped[1:] & dropped[:-1])
    if pair.size:
        return keep, f'samples {int(pair[0])} and {int(pair[0]) + 1} are both out of order'
    return keep, None


def dropped_warning(t, keep):
    """Return the warning naming the first samples dropped by :func:`drop_isolated`."""
    idx = np.flatnonzero(~keep)
    named = ', '.join(f'{i} (t={t[i]:.9f} s)' for i in idx[:NAMED].tolist())
    more = ', ...' if idx.size > NAMED else ''
    return (f'{idx.size} isolated out-of-order or repeated time stamp(s) dropped (a stamp '
            f'not after every earlier one: damaged messages): sample(s) {named}{more}')


def without_dropped(samples, keep):
    """Return a record (a dataclass with ``t``, ``data``, ``warnings``) without the dropped."""
    if keep is None:
        return samples
    return replace(samples, t=samples.t[keep], data=samples.data[keep],
                   warnings=[*samples.warnings, dropped_warning(samples.t, keep)])
