"""
The simulator exporters: Gazebo's SDF ``<imu>`` noise and PX4 SITL's gazebo_imu_plugin.

:data:`SIM_EXPORTERS` is registered by :mod:`imu_allan.report.exporters` (``--export
gazebo,px4``); this module only needs the registry's :class:`Exporter` (the dependency points
one way).  The files and their conversions are :func:`imu_allan.formats.gazebo_sdf.export_gazebo`
and ``export_px4``.  Each file starts with the common provenance header (an XML comment), then
the writer's own notes on the simulator's terms.

Both simulators model an axis as white noise plus ONE first-order Gauss-Markov bias; with
``--overbound`` that model's parameters (N, sigma, tau_c) are chosen by
:func:`imu_allan.core.overbound.overbound` (tau_c profiled): per axis for Gazebo, and for PX4
(one value per sensor) over the envelope of the sensor's axes, so that the one set of values
bounds every axis.  The factors in the header are against the file the raw fit would give.
"""

import functools
import math

from .export_registry import Exporter
from ..core.model import NoiseModel
from ..formats.gazebo_sdf import (
    export_gazebo,
    export_px4,
    GAZEBO_FILE,
    ModelInput,
    PX4_FILE,
    PX4_KEYS,
)

#: The simulators' noise model: white noise plus one Gauss-Markov bias per axis.
SIM_MODEL = ('white_noise', 'gauss_markov')


def _source(values):
    return values.analysis if values.analysis is not None else values.fit


def _overbound_source(values, per_sensor):
    """Return the overbounding white + Gauss-Markov terms per axis (per sensor: envelope)."""
    terms = {}
    for sensor in ('gyro', 'accel'):
        axes = values.axes(sensor)
        for axis in axes:
            fit = values.overbound_fit(axes if per_sensor else axis, SIM_MODEL)
            terms[axis] = {'white_noise': dict(fit.terms['white_noise'])}
            if fit.value('gauss_markov', 'sigma') > 0:
                terms[axis]['gauss_markov'] = {k: float(v) for k, v in
                                               fit.terms['gauss_markov'].items()}
    # the overbounding model in place of the fit: no upper limits (every term is set)
    return ModelInput(NoiseModel(terms, values.fitted_rate_hz), values.fitted_rate_hz,
                      values.fit.result, source=values.source)


def _factors(values, raw, bounded, per_sensor):
    """Record per written key the factor against the raw file's value and the tight taus."""
    if not per_sensor:
        for axis, written in bounded['axes'].items():
            fit = values.overbound_fit(axis, SIM_MODEL)
            for key in ('stddev', 'dynamic_bias_stddev'):
                before = raw['axes'].get(axis, {}).get(key, math.nan)
                values.note_overbound(f'{axis}.{key}', axis,
                                      written[key] / before if before > 0 else math.nan,
                                      fit.tight_tau)
        return
    for sensor, (n_key, rw_key, _tau_key, _on_key) in PX4_KEYS.items():
        axes = values.axes(sensor)
        for key in (n_key, rw_key) if axes else ():
            before = raw.get(key, math.nan)
            fit = values.overbound_fit(axes, SIM_MODEL)
            values.note_overbound(key, '+'.join(axes),
                                  bounded[key] / before if before > 0 else math.nan,
                                  fit.tight_tau)


def _made(write, per_axis, values):
    """Return ``write``'s (values dict, file text) of ``values``: raw, or overbounded."""
    source = _source(values)
    if values.overbound is None:
        return write(source, values.rate_hz, values.inflate, values.source)
    bounded = _overbound_source(values, not per_axis)
    raw = write(source, values.rate_hz, (1.0, 1.0), values.source)[0]
    plain = write(bounded, values.rate_hz, (1.0, 1.0), values.source)[0]
    _factors(values, raw, plain, not per_axis)
    return write(bounded, values.rate_hz, values.inflate, values.source)


def _build(write, per_axis, values):
    return _made(write, per_axis, values)[0]


def _render(write, per_axis, file_name, _data, header, values):
    text = _made(write, per_axis, values)[1]
    lines = ''.join(f'  {line.replace("--", "- -")}\n' for line in header)
    return {file_name: f'<!--\n{lines}-->\n{text}'}


def _exporter(name, file_name, consumer, conversion, write, per_axis):
    # (partials of module functions: picklable, as the record's overbound request must be)
    return Exporter(name, (file_name,), consumer, 'per sample' if per_axis else 'continuous',
                    conversion, functools.partial(_build, write, per_axis),
                    functools.partial(_render, write, per_axis, file_name), per_axis=per_axis,
                    model=SIM_MODEL, overbound_over='axis' if per_axis else 'sensor')


#: The simulators' exporters, in the order the registry lists them.
SIM_EXPORTERS = (
    _exporter('gazebo', GAZEBO_FILE, 'Gazebo (gz-sensors)',
              'stddev = N sqrt(f) per sample; dynamic_bias_stddev = Gauss-Markov driving density; '
              'precision = sqrt(12) Q f', export_gazebo, per_axis=True),
    _exporter('px4', PX4_FILE, 'PX4 SITL (gazebo_imu_plugin)',
              'NoiseDensity = N; RandomWalk = Gauss-Markov driving density; '
              'BiasCorrelationTime = tau_c', export_px4, per_axis=False),
)
