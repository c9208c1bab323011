"""From an ``analyze`` report to the rows of the history tables (ROS-free, no DuckDB needed)."""

import math
from pathlib import Path

from .db import utc
from ..core.units import si_unit, TERM_PARAMETERS


def namespace_of(topic):
    """
    Return the robot/namespace part of an Imu topic name ('' when it has none).

    The namespace is what precedes the ``imu`` segment (``/robot3/imu/data_raw`` ->
    ``robot3``); a topic with no ``imu`` segment keeps all but its last segment
    (``/robot3/sensors/data`` -> ``robot3/sensors``).
    """
    parts = [p for p in (topic or '').split('/') if p]
    if 'imu' in parts:
        return '/'.join(parts[:parts.index('imu')])
    return '/'.join(parts[:-1])


def imu_id_of(topic, frame_id, input_path):
    """``namespace/frame_id`` (or ``frame_id``); inputs without a frame id use their file name."""
    name = frame_id or Path(str(input_path).rstrip('/')).stem
    ns = namespace_of(topic)
    return f'{ns}/{name}' if ns else name


def _finite(value):
    return float(value) if value is not None and math.isfinite(value) else None


def measurement_rows(report, input_path, analyzed_at, imu_id=None):
    """
    Return the ``measurements`` rows (dicts) of one ``analyze`` JSON report.

    Detected terms with their 68.3 % intervals (one row per parameter), then the 95 % upper
    limits of the undetected ones (``detected`` false).  ``input_path``: as stored in the
    ``input`` column (absolute); ``analyzed_at``: naive UTC; ``imu_id`` overrides the id
    derived from the topic's namespace and the Imu frame_id.
    """
    rec = report.get('recording', {})
    topic = rec.get('topic') or None
    base = {
        'input': input_path, 'topic': topic,
        'imu_id': imu_id or imu_id_of(topic, rec.get('frame_id'), input_path),
        'start_utc': utc(rec['start_s']) if rec.get('start_s') is not None else None,
        'duration_s': report['duration_s'], 'rate_hz': report['sample_rate_hz'],
        'static': report['verdict']['static'], 'analyzed_at': analyzed_at,
    }
    rows = []
    for axis, block in report['axes'].items():
        for term, entry in block['terms'].items():
            main, *extra = TERM_PARAMETERS[term]
            params = [(main, entry)] + [(name, entry[name]) for name in extra]
            for name, e in params:
                rows.append(dict(base, axis=axis, term=term, param=name,
                                 value=_finite(e['value']), ci_low=_finite(e['ci'][0]),
                                 ci_high=_finite(e['ci'][1]), unit=e['unit'], detected=True))
    for axis, limits in report.get('upper_limits', {}).items():
        for term, value in limits.items():
            rows.append(dict(base, axis=axis, term=term, param='value', value=_finite(value),
                             ci_low=None, ci_high=None, unit=si_unit(axis, term),
                             detected=False))
    return rows
