"""Kalibr ``imu.yaml``: the four continuous-time noise keys (worst axis, upper limits), as text."""

import math
from pathlib import Path

from ..core.export_values import ExportValues

KEYS = (('gyro', 'gyroscope'), ('accel', 'accelerometer'))
TERMS = (('noise_density', 'white_noise'), ('random_walk', 'rate_random_walk'))


def kalibr_values(analysis):
    """
    Kalibr ``imu.yaml`` values: continuous-time, the worst axis per sensor.

    ``*_noise_density`` is the white-noise coefficient N; ``*_random_walk`` is the rate random
    walk K (bias random walk).  Where the data do not show a term, its 95 % upper limit is used
    (Kalibr refuses zeros) and listed in ``upper_limits``; a key whose axis's model the adequacy
    test rejects is listed in ``inadequate``.  Returns ``(values, per_axis)``;
    per-axis entries are ``(value, is_upper_limit)``.  ``analysis`` may also be an
    :class:`ExportValues` (inflated, another rate).
    """
    values = analysis if isinstance(analysis, ExportValues) else ExportValues(analysis)
    out = {'update_rate': values.rate_hz, 'upper_limits': [], 'inadequate': []}
    per_axis = {}
    for sensor, prefix in KEYS:
        for key, term in TERMS:
            name = f'{prefix}_{key}'
            per_axis[name] = {a: values.value(a, term) for a in values.axes(sensor)}
            out[name] = values.worst(sensor, term, name)
            if values.used[name]['upper']:
                out['upper_limits'].append(name)
            if values.used[name]['inadequate']:
                out['inadequate'].append(name)
    return out, per_axis


def kalibr_yaml_text(values, per_axis, topic='/imu/data_raw', header=()):
    """Return the text of a Kalibr ``imu.yaml`` from :func:`kalibr_values` output."""
    lines = [f'# {line}' for line in header]
    lines += ['# Kalibr IMU noise model from imu_allan (continuous-time, SI units).',
              '# *_noise_density = white noise N (rad/s/sqrt(Hz), m/s^2/sqrt(Hz));',
              '# *_random_walk = bias random walk K (rad/s^2/sqrt(Hz), m/s^3/sqrt(Hz));',
              '# the worst (largest) axis of each sensor, as Kalibr users expect.',
              '# Kalibr needs all four > 0: where the data do not show a term, its 95 % upper',
              '# limit is written (marked below); null means not even a limit was found.']
    for key in values.get('inadequate', []):
        lines.append(f'# {key}: MODEL INADEQUATE on its axis (report.json fit.adequacy): '
                     'the noise model does not describe that curve; do not trust this value')
    for key, axes in per_axis.items():
        text = ', '.join(f'{a} {v:.6g}' + (' (upper limit, not detected)' if bound else '')
                         if math.isfinite(v) else f'{a} not detected'
                         for a, (v, bound) in axes.items())
        lines.append(f'# {key} per axis: {text}')
    lines.append(f'rostopic: {topic}')
    lines.append(f'update_rate: {values["update_rate"]:.6g}')
    for key in ('accelerometer_noise_density', 'accelerometer_random_walk',
                'gyroscope_noise_density', 'gyroscope_random_walk'):
        value = values.get(key)
        lines.append(f'{key}: {value:.6e}' if value is not None else f'{key}: null')
    return '\n'.join(lines) + '\n'


def write_kalibr_yaml(path, analysis, topic='/imu/data_raw'):
    """Kalibr ``imu.yaml``: continuous-time values of the worst axis, per-axis in comments."""
    values, per_axis = kalibr_values(analysis)
    Path(path).write_text(kalibr_yaml_text(values, per_axis, topic), encoding='utf-8')
