"""
The simulator exporters: Gazebo's SDF ``<imu>`` noise and PX4 SITL's gazebo_imu_plugin.

Registered in :mod:`imu_allan.report.exporters` (``--export gazebo,px4``); the files and their
conversions are :func:`imu_allan.formats.gazebo_sdf.export_gazebo` and ``export_px4``.  Each
file starts with the common provenance header (an XML comment), then the writer's own notes on
the simulator's terms.
"""

from .exporters import Exporter, register
from ..formats.gazebo_sdf import export_gazebo, export_px4, GAZEBO_FILE, PX4_FILE


def _source(values):
    return values.analysis if values.analysis is not None else values.fit


def _exporter(name, file_name, consumer, conversion, write, per_axis):
    def build(values):
        return write(_source(values), values.rate_hz, values.inflate, values.source)[0]

    def render(_data, header, values):
        text = write(_source(values), values.rate_hz, values.inflate, values.source)[1]
        lines = ''.join(f'  {line.replace("--", "- -")}\n' for line in header)
        return {file_name: f'<!--\n{lines}-->\n{text}'}
    return register(Exporter(name, (file_name,), consumer, 'per sample' if per_axis else
                             'continuous', conversion, build, render, per_axis=per_axis))


_exporter('gazebo', GAZEBO_FILE, 'Gazebo (gz-sensors)',
          'stddev = N sqrt(f) per sample; dynamic_bias_stddev = Gauss-Markov driving density; '
          'precision = sqrt(12) Q f', export_gazebo, per_axis=True)
_exporter('px4', PX4_FILE, 'PX4 SITL (gazebo_imu_plugin)',
          'NoiseDensity = N; RandomWalk = Gauss-Markov driving density; '
          'BiasCorrelationTime = tau_c', export_px4, per_axis=False)
