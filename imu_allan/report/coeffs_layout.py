"""
The numbers on ``imu/allan_coeffs`` and ``imu/allan_deviation`` (the contract layouts).

The layouts are documented in docs/interfaces.md (Topics).  ``imu/allan_coeffs``: dims
``axis`` (6) x ``term`` (5: :data:`~imu_allan.core.units.IEEE_TERMS`) x ``stat`` (3: value,
ci_low, ci_high; 68.3 %), row-major, SI, continuous-time, NaN where a term is not resolved;
after those 90 numbers, which the dims describe, :data:`ADEQUACY_VALUES` (each axis's adequacy
p) and :data:`LIMIT_VALUES` (axis x term 95 % upper limits of the unresolved terms), read with
:func:`decode_adequacy` and :func:`decode_limits` (None from a publisher without them).
``imu/allan_deviation`` (and ``imu/allan_deviation/<kind>``): dims ``row`` (7: tau, then the
six axes) x ``tau``.  The node encodes with these functions; users and tools (``monitor``)
decode with :func:`decode_coefficients` and :func:`decode_deviation`, which check the layout,
or :func:`decode_table` for the bare reshape.
"""

import math

import numpy as np

from ..core.units import AXES, conventional, IEEE_TERMS, si_unit
from ..errors import InputError

COEFF_LABELS = ('axis', 'term', 'stat')
#: Values after the coefficient table: the adequacy p of each axis, then the upper limits
#: (module docstring).
ADEQUACY_VALUES = len(AXES)
LIMIT_VALUES = len(AXES) * len(IEEE_TERMS)
DEVIATION_LABELS = ('row', 'tau')
STATS = ('value', 'ci_low', 'ci_high')


def coefficient_table(fitted, axes=AXES):
    """
    Return the ``imu/allan_coeffs`` table (axis, term, stat) = (A, 5, 3), SI, NaN if absent.

    ``fitted`` is a :class:`~imu_allan.core.fit.FittedModel` or None (all NaN).
    """
    out = np.full((len(axes), len(IEEE_TERMS), 3), np.nan)
    if fitted is None:
        return out
    for i, axis in enumerate(axes):
        if axis not in fitted.fits:
            continue
        for j, term in enumerate(IEEE_TERMS):
            value = fitted.value(axis, term)
            if math.isfinite(value):
                lo, hi = fitted.interval(axis, term)
                out[i, j] = (value, lo, hi)
    return out


def adequacy_values(fitted, axes=AXES):
    """Return the trailing block of ``imu/allan_coeffs``: each axis's adequacy p (NaN: none)."""
    out = np.full(len(axes), np.nan)
    for i, axis in enumerate(axes):
        adequacy = fitted.adequacy(axis) if fitted is not None else None
        if adequacy is not None and math.isfinite(adequacy.p):
            out[i] = adequacy.p
    return out


def limit_values(fitted, axes=AXES):
    """Return the last block of ``imu/allan_coeffs``: (axis, term) 95 % upper limits, flat."""
    out = np.full((len(axes), len(IEEE_TERMS)), np.nan)
    for i, axis in enumerate(axes if fitted is not None else ()):
        for term, limit in fitted.limits(axis).items():
            out[i, IEEE_TERMS.index(term)] = limit
    return out.ravel()


def alarm_lows(fitted, axes=AXES):
    """
    Return the (axis, term) lower ends the budget levels rest on (not in the message; NaN).

    :meth:`~imu_allan.core.fit.FittedModel.alarm_low`; None without a fit.
    """
    if fitted is None:
        return None
    out = np.full((len(axes), len(IEEE_TERMS)), np.nan)
    for i, axis in enumerate(axes):
        if axis in fitted.fits:
            out[i] = [fitted.alarm_low(axis, term) for term in IEEE_TERMS]
    return out


def _trailing(source, dims, skip, count):
    """Return the ``count`` values after the table and ``skip`` more; None if they are absent."""
    data, dims = _layout(source, dims, 'imu/allan_coeffs')
    values = np.asarray(data, dtype=float)
    start = int(np.prod([size for _, size in dims])) + skip
    return None if values.size < start + count else values[start:start + count]


def decode_limits(source, dims=None):
    """
    Return the (6, 5) 95 % upper limits of ``imu/allan_coeffs`` (SI; NaN: resolved or none).

    None when the message has no limit block (an older publisher).
    """
    limits = _trailing(source, dims, ADEQUACY_VALUES, LIMIT_VALUES)
    return None if limits is None else limits.reshape(len(AXES), len(IEEE_TERMS))


def decode_adequacy(source, dims=None):
    """
    Return each axis's adequacy p from ``imu/allan_coeffs`` (6,); None without its block.

    The model of an axis describes its curve when p >= 0.001 (:data:`ADEQUACY_LEVEL` of
    :mod:`imu_allan.core.fit.adequacy`).
    """
    return _trailing(source, dims, 0, ADEQUACY_VALUES)


def deviation_table(result, axes=AXES):
    """
    Return the ``imu/allan_deviation`` numbers: array (1 + len(axes), T): tau then ADEV per axis.

    Axes missing from ``result`` are NaN rows.  ``result`` may also be another deviation
    (``.dev``, e.g. a :class:`~imu_allan.core.live.streaming.StreamingDeviation` for
    ``imu/allan_deviation/<kind>``, the same layout).
    """
    if result is None:
        return np.zeros((1 + len(axes), 0))
    out = np.full((1 + len(axes), result.tau.size), np.nan)
    out[0] = result.tau
    dev = result.dev if hasattr(result, 'dev') else result.adev
    for i, axis in enumerate(axes):
        if axis in result.axes:
            out[1 + i] = dev[:, result.axis_index(axis)]
    return out


def decode_table(data, dims, trailing=0):
    """
    Array of a row-major multiarray payload: ``data`` (flat) and ``dims`` ((label, size)...).

    Raises ValueError when the sizes do not match the data (``data_offset`` must be 0);
    ``trailing`` values after the table are allowed (the adequacy block of
    ``imu/allan_coeffs``), and after those the limit block.
    """
    sizes = tuple(int(size) for _, size in dims)
    values = np.asarray(data, dtype=float)
    table = int(np.prod(sizes))
    allowed = {table, table + trailing}
    if trailing:  # and the limit block after the adequacy block
        allowed.add(table + trailing + LIMIT_VALUES)
    if values.size not in allowed:
        raise ValueError(f'layout {sizes} does not match {values.size} values')
    return values[:table].reshape(sizes)


def _layout(source, dims, topic):
    """``(flat data, ((label, size), ...))`` of a message or of data + dims."""
    if dims is None:
        layout = getattr(source, 'layout', None)
        if layout is None:
            raise InputError(topic, 'neither a Float64MultiArray nor data with dims')
        if layout.data_offset:
            raise InputError(topic, f'data_offset {layout.data_offset}, expected 0')
        dims = [(d.label, d.size) for d in layout.dim]
        source = source.data
    return source, tuple((str(label), int(size)) for label, size in dims)


def _check_labels(dims, labels, topic):
    if tuple(label for label, _ in dims) != labels:
        raise InputError(topic, f'dimension labels {[label for label, _ in dims]}, expected '
                                f'{list(labels)}')


def decode_coefficients(source, dims=None):
    """
    Return the ``imu/allan_coeffs`` array (axis, term, stat) = (6, 5, 3), SI, NaN if not detected.

    ``source`` is a ``std_msgs/Float64MultiArray`` (rclpy or rosbags: the same field names), or
    the flat data with ``dims`` as ``((label, size), ...)``.  Labels and sizes are checked
    against the contract; a mismatch raises InputError naming the topic.
    """
    data, dims = _layout(source, dims, 'imu/allan_coeffs')
    _check_labels(dims, COEFF_LABELS, 'imu/allan_coeffs')
    expected = (len(AXES), len(IEEE_TERMS), len(STATS))
    if tuple(size for _, size in dims) != expected:
        raise InputError('imu/allan_coeffs', f'sizes {[size for _, size in dims]}, expected '
                                             f'{list(expected)}')
    try:
        return decode_table(data, dims, ADEQUACY_VALUES)
    except ValueError as exc:
        raise InputError('imu/allan_coeffs', str(exc)) from None


def decode_deviation(source, dims=None, topic='imu/allan_deviation'):
    """
    ``(tau (T,), dev (T, 6))`` of ``imu/allan_deviation`` (s, and rad/s or m/s^2).

    The same for ``imu/allan_deviation/<kind>`` (mdev, ohdev: the same layout); ``topic``
    names it in errors.
    """
    data, dims = _layout(source, dims, topic)
    _check_labels(dims, DEVIATION_LABELS, topic)
    if dims[0][1] != 1 + len(AXES):
        raise InputError(topic, f'{dims[0][1]} rows, expected {1 + len(AXES)}')
    try:
        table = decode_table(data, dims)
    except ValueError as exc:
        raise InputError(topic, str(exc)) from None
    return table[0], table[1:].T


def coefficient_terms(table, axes=AXES):
    """
    Return detected terms of a decoded coefficient table, per axis, in ``analyze --json``'s shape.

    ``{axis: {term: {value, ci, unit, time, conventional: {value, unit, ci}}}}``; terms that
    are NaN (not detected) are left out; an interval end that is NaN becomes None (JSON null).
    """
    out = {}
    for i, axis in enumerate(axes):
        terms = {}
        for j, term in enumerate(IEEE_TERMS):
            value, low, high = (float(v) for v in table[i, j])
            if not math.isfinite(value):
                continue
            conv, unit = conventional(axis, term, value)
            ci = [v if math.isfinite(v) else None for v in (low, high)]
            terms[term] = {'value': value, 'ci': ci, 'unit': si_unit(axis, term),
                           'time': 'continuous',
                           'conventional': {'value': conv, 'unit': unit,
                                            'ci': [None if v is None else
                                                   conventional(axis, term, v)[0]
                                                   for v in ci]}}
        out[axis] = terms
    return out
