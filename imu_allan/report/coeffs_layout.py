"""The numbers on ``imu/allan_coeffs`` and ``imu/allan_deviation`` (the contract layouts).

``imu/allan_coeffs``: dims ``axis`` (6) x ``term`` (5: :data:`~imu_allan.core.units.IEEE_TERMS`)
x ``stat`` (3: value, ci_low, ci_high; 68.3 %), row-major, ``data_offset`` 0, SI units,
continuous-time coefficients, NaN where a term is not detected.  ``imu/allan_deviation``: dims
``row`` (7: tau, then the six axes) x ``tau``.  The node encodes with these functions; users
and tools decode with :func:`decode_table`.
"""

import math

import numpy as np

from ..core.units import AXES, IEEE_TERMS

COEFF_LABELS = ('axis', 'term', 'stat')
DEVIATION_LABELS = ('row', 'tau')
STATS = ('value', 'ci_low', 'ci_high')


def coefficient_table(fitted, axes=AXES):
    """The ``imu/allan_coeffs`` numbers: array (axis, term, stat) = (A, 5, 3), NaN if absent.

    ``stat`` is ``value, ci_low, ci_high`` (68.3 %); terms in
    :data:`~imu_allan.core.units.IEEE_TERMS` order; SI units.  ``fitted`` is a
    :class:`~imu_allan.core.fit.FittedModel` or None (all NaN).
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


def deviation_table(result, axes=AXES):
    """The ``imu/allan_deviation`` numbers: array (1 + len(axes), T): tau then ADEV per axis.

    Axes missing from ``result`` are NaN rows.
    """
    if result is None:
        return np.zeros((1 + len(axes), 0))
    out = np.full((1 + len(axes), result.tau.size), np.nan)
    out[0] = result.tau
    for i, axis in enumerate(axes):
        if axis in result.axes:
            out[1 + i] = result.adev[:, result.axis_index(axis)]
    return out


def decode_table(data, dims):
    """Array of a row-major multiarray payload: ``data`` (flat) and ``dims`` ((label, size)...).

    Raises ValueError when the sizes do not match the data (``data_offset`` must be 0).
    """
    sizes = tuple(int(size) for _, size in dims)
    values = np.asarray(data, dtype=float)
    if int(np.prod(sizes)) != values.size:
        raise ValueError(f'layout {sizes} does not match {values.size} values')
    return values.reshape(sizes)
