"""
The ``temperature`` section of report.json: bias-versus-temperature slopes and moves.

Filled when a bag input has a ``sensor_msgs/Temperature`` topic (read with
:mod:`imu_allan.formats.temperature_bag`); the numerics are in
:mod:`imu_allan.core.temperature`.  Schema::

    "temperature": {"topic": "/imu/temperature", "n_readings": int, "range_c": [lo, hi],
                    "slopes": {"gyro_x": {"value": b, "ci": [lo, hi], "unit": "rad/s/K",
                                          "stderr": se, "block_s": s, "n_blocks": n}, ...},
                    "changes": [{"t_start_s", "t_end_s", "from_c", "to_c"}, ...],
                    "coincidences": [{"event": "change"|"warmup", "t_s", "axis",
                                      "temperature_change": index or null}, ...],
                    "notes": [...], "method": "..."}

Slopes are SI per kelvin (= per deg C of difference), 68.3 % intervals; times in s from the
first IMU sample; ``range_c`` over the readings inside the IMU record (all of them when none
is).
"""

from pathlib import Path

import numpy as np

from ..core.temperature import bias_slopes, coinciding_change, temperature_changes
from ..errors import InputError

METHOD = ('least-squares slope of block means of the rate on the temperature interpolated '
          'at the block centres; standard error from simulating the Allan noise model fitted '
          'to the residuals (accounts for correlated noise); 68.3 % interval')


def add_temperature(report, path, fmt, samples, analysis):
    """
    Add ``report['temperature']`` when ``path`` is a bag with a Temperature topic.

    Also sets ``samples.temperature = (t, deg C)``.  Anything else (not a bag, no topic, an
    unreadable topic) leaves the report as it is.
    """
    from ..formats.readers import detect_format
    from ..formats.temperature_bag import read_temperature
    p = Path(path)
    if not (p.is_dir() or p.is_file()):
        return                      # a FIFO was read once already
    try:
        kind = detect_format(path) if fmt == 'auto' else fmt
        if kind not in ('rosbag2', 'ros1'):
            return
        reading = read_temperature(path, imu_topic=samples.topic or '',
                                   topic_types=samples.topic_types)
    except InputError:
        return
    if reading is None:
        return
    topic, t, celsius = reading
    samples.temperature = (t, celsius)
    report['temperature'] = temperature_json(topic, t, celsius, samples, analysis)
    relate_events(report)


def temperature_json(topic, t, celsius, samples, analysis):
    """
    Return the report section for temperatures ``(t, celsius)`` beside the record.

    The slopes are regressed on every sample read (``samples``), a warm-up the Allan estimate
    left out included: where the bias settles with the temperature, that is the signal.
    """
    imu_t = samples.t
    inside = (t >= imu_t[0]) & (t <= imu_t[-1])
    shown = celsius[inside] if inside.any() else celsius
    slopes, notes = bias_slopes(imu_t, np.asarray(samples.data, dtype=float),
                                analysis.rate_hz, analysis.axes, t, celsius)
    changes = temperature_changes(t - imu_t[0], celsius)
    return {'topic': topic, 'n_readings': int(t.size),
            'range_c': [float(np.min(shown)), float(np.max(shown))],
            'slopes': {axis: est.to_json() for axis, est in slopes.items()},
            'changes': [c.to_json() for c in changes], 'coincidences': [],
            'notes': list(notes), 'method': METHOD}


def relate_events(report, margin_fraction=0.05):
    """
    Say which detected changes and warm-up coincide with a temperature move.

    Reads ``report['dynamic']['changes']`` (``t_s``, ``axis``) and
    ``report['verdict']['warmup_s']`` when present; a change coincides with a move whose span
    holds its time, widened by ``margin_fraction`` of the record; a warm-up with a move that
    starts before it ends (same margin).  Fills ``report['temperature']['coincidences']``.
    """
    section = report.get('temperature')
    if not section:
        return
    from ..core.temperature import TemperatureChange
    changes = [TemperatureChange(**c) for c in section['changes']]
    margin = margin_fraction * float(report.get('duration_s') or 0.0)
    out = []
    for event in (report.get('dynamic') or {}).get('changes') or []:
        t_s = event.get('t_s')
        if t_s is None:
            continue
        out.append({'event': 'change', 't_s': t_s, 'axis': event.get('axis'),
                    'temperature_change': coinciding_change(t_s, changes, margin)})
    warmup = (report.get('verdict') or {}).get('warmup_s')
    if warmup:
        hit = next((i for i, c in enumerate(changes) if c.t_start_s <= warmup + margin), None)
        out.append({'event': 'warmup', 't_s': warmup, 'axis': None, 'temperature_change': hit})
    section['coincidences'] = out


def temperature_sentence(report):
    """Console lines about the temperature section ('' without one), with a leading newline."""
    section = report.get('temperature')
    if not section:
        return ''
    lo, hi = section['range_c']
    lines = [f'temperature ({section["topic"]}): {lo:.1f} .. {hi:.1f} deg C, '
             f'{len(section["changes"])} move(s) of 1 deg C or more']
    for axis, s in section['slopes'].items():
        lines.append(f'  {axis}: bias slope {s["value"]:.3g} {s["unit"]} '
                     f'(68.3 %: {s["ci"][0]:.3g} .. {s["ci"][1]:.3g})')
    lines += [f'  note: {n}' for n in section['notes']]
    return '\n' + '\n'.join(lines)
