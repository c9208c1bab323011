"""
JSON as the standard has it: no NaN or Infinity, which many parsers refuse.

Python's ``json`` writes ``NaN`` for a float that is not a number; a report that does is not
JSON to a strict reader (JavaScript's ``JSON.parse``, ``jq``, Rust's serde).  Every report
the package writes goes through :func:`dumps`: a number that is not finite becomes ``null``
("not measured"), and anything else that cannot be written is an error, not a silent NaN.
"""

import json
import math

import numpy as np


def finite_or_none(obj):
    """Return ``obj`` with every non-finite float (nested) replaced by None."""
    if isinstance(obj, dict):
        return {k: finite_or_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite_or_none(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def dumps(obj, **kwargs):
    """:func:`json.dumps` of :func:`finite_or_none` of ``obj``, refusing NaN (``allow_nan``)."""
    return json.dumps(finite_or_none(obj), allow_nan=False, **kwargs)
