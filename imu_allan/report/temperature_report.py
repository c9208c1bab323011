"""
The ``temperature`` section of report.json: bias-versus-temperature slopes and moves.

Filled when a bag input has a ``sensor_msgs/Temperature`` topic (read with the Imu samples,
:mod:`imu_allan.formats.temperature_bag`); renders the record's
:class:`~imu_allan.core.record.TemperatureAnalysis` (numerics in
:mod:`imu_allan.core.temperature`, coincidences in :mod:`imu_allan.core.record`).  The schema
is in docs/interfaces.md (JSON, ``temperature``): slopes SI per kelvin with 68.3 % intervals,
times in s from the first IMU sample, ``range_c`` over the readings inside the IMU record.
"""

#: How the slopes are estimated (report.json ``method``).
METHOD = ('least-squares slope of block means of the rate on the temperature interpolated '
          'at the block centres; standard error from simulating the Allan noise model fitted '
          'to the residuals (accounts for correlated noise); 68.3 % interval')


def temperature_json(part):
    """Return the report section of a :class:`~imu_allan.core.record.TemperatureAnalysis`."""
    return {'topic': part.topic, 'n_readings': int(part.t.size),
            'range_c': list(part.range_c),
            'slopes': {axis: est.to_json() for axis, est in part.slopes.items()},
            'changes': [c.to_json() for c in part.changes],
            'coincidences': [c.to_json() for c in part.coincidences],
            'notes': list(part.notes), 'method': METHOD}


def temperature_sentence(part):
    """Return the console lines about the temperature."""
    lo, hi = part.range_c
    lines = [f'temperature ({part.topic}): {lo:.1f} .. {hi:.1f} deg C, '
             f'{len(part.changes)} move(s) of 1 deg C or more']
    for axis, s in part.slopes.items():
        lines.append(f'  {axis}: bias slope {s.value:.3g} {s.unit} '
                     f'(68.3 %: {s.ci[0]:.3g} .. {s.ci[1]:.3g})')
    lines += [f'  note: {n}' for n in part.notes]
    return '\n'.join(lines)
