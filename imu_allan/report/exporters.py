"""
Exporters: the fitted noise model in the keys, units and time base each consumer reads.

Which consumer wants what (keys, units, continuous-time density or per-sample value, and the
line of its source where it converts) is documented in ``docs/exports.md``; each builder below
cites that source line too.  The rules every file shares (upper limits, inflation, the worst
axis) live in :mod:`imu_allan.core.export_values`; every file starts with the provenance of
:func:`header_lines` (an ``imu_allan`` list of lines in JSON).

Registry
--------
:data:`EXPORTERS` (in :mod:`.export_registry`) maps a name to an :class:`Exporter` (its fields
are described there).  ``build(values) -> dict`` turns an
:class:`~imu_allan.core.export_values.ExportValues` into the data the file holds (that dict is
what :func:`export` returns); ``render(data, header, values)`` returns ``{file name: text}``
for the files in ``files`` (``header``: the comment lines of :func:`header_lines`, to be
written first).  Adding a consumer (for example Gazebo's SDF ``<imu>`` element and PX4's
gazebo_imu_plugin block) is two functions and one call in the module that defines them::

    from imu_allan.report.export_registry import Exporter
    GAZEBO = Exporter('gazebo', ('gazebo_imu.sdf',), 'Gazebo (gz-sensors)', 'per sample',
                      'stddev = N sqrt(f); dynamic_bias_stddev = sigma sqrt(2 / tau_c)',
                      build=_gazebo_build, render=_gazebo_render)

plus its registration at the end of this one (:mod:`.sim_exporters` does so), so that
``--export`` and ``all`` see it; that module imports only the registry, never this one.  A
builder asks ``values.worst(sensor, term, key)`` or ``values.per_axis(sensor, term, key)``
(and ``values.value(axis, term, param)`` for Gauss-Markov parameters); the header's axis rule
and upper-limit marks follow from those calls.
"""

from dataclasses import dataclass, replace
import json
import math
from pathlib import Path

from .export_registry import Exporter, EXPORTERS, register
from .sim_exporters import SIM_EXPORTERS
from ..core.export_values import ExportValues
from ..core.units import discrete_random_walk_step, discrete_white_std, STANDARD_GRAVITY

EXPORT_DIR = 'export'


def exporter_names():
    """Return registered exporter names, in registration order."""
    return list(EXPORTERS)


@dataclass(frozen=True)
class ExportOptions:
    """
    What ``--export`` writes (the command's export options, as one object).

    Exporter ``names`` (registry order as given), ``inflate = (white, walk)`` on the standard
    deviations and, with ``overbound``, each consumer model's overbounding values up to
    ``horizon_s`` (s; None: the longest measured averaging time).
    """

    names: tuple = ()
    inflate: tuple = (1.0, 1.0)
    overbound: bool = False
    horizon_s: float = None

    def overbound_request(self):
        """Return what the record must overbound for these exports (None: nothing)."""
        if not (self.overbound and self.names):
            return None
        from ..core.record import OverboundRequest
        exporters = [exporter_of(n) for n in self.names]
        models = dict.fromkeys((tuple(e.model), e.overbound_over) for e in exporters)
        return OverboundRequest(tuple(models), self.horizon_s,
                                tuple((e.name, e.model, e.build) for e in exporters),
                                self.inflate)


def exporter_of(name):
    """Return the registered :class:`Exporter` ``name``; ValueError if there is none."""
    if name not in EXPORTERS:
        raise ValueError(f'unknown exporter {name!r} (known: {", ".join(EXPORTERS)})')
    return EXPORTERS[name]


# ----------------------------------------------------------------------------- header


def _version():
    from .. import __version__
    return __version__


def header_lines(exporter, values):
    """Return the provenance every file starts with, as lines without the comment marker."""
    if exporter.per_axis:
        axis_rule = 'per axis (x, y, z)'
    else:
        axis_rule = 'worst (largest) axis per sensor: ' + ', '.join(
            f'{k} from {u["axes"][0]}' for k, u in values.used.items() if u['axes'])
    white, walk = values.inflate
    inflation = ('none (x1)' if white == walk == 1.0 else
                 f'white noise x{white:g}, bias (random walk, instability) x{walk:g} '
                 '(standard deviations)'
                 + (', on top of the overbound' if values.overbound is not None else ''))
    lines = [f'{exporter.consumer} IMU noise parameters from imu_allan {_version()}.',
             f'input: {values.source}',
             f'rate: {values.rate_hz:g} Hz',
             f'time base: {exporter.time_base}; conversion (f = rate in Hz, N white noise, '
             f'K rate random walk, B bias instability; SI): {exporter.conversion}',
             f'axes: {axis_rule}',
             f'inflation: {inflation}']
    if values.rate_hz != values.fitted_rate_hz:
        lines.append(f'warning: model measured at {values.fitted_rate_hz:g} Hz, converted for '
                     f'{values.rate_hz:g} Hz: valid only if the IMU filters to the new band '
                     'before decimating (Kalibr wiki "IMU Noise Model")')
    lines += overbound_lines(exporter, values)
    for key, axes in values.upper_limit_keys().items():
        lines.append(f'{key}: not detected on {", ".join(axes)}: its 95 % upper limit is '
                     'written (UPPER LIMIT)')
    for key, axes in values.inadequate_keys().items():
        lines.append(f'{key}: from {", ".join(axes)}, whose noise model does not describe its '
                     'Allan curve (adequacy test, report.json fit.adequacy): MODEL INADEQUATE, '
                     'the value is not reliable')
    for key in [k for k, u in values.used.items() if not u['axes']]:
        lines.append(f'{key}: not measured (no such axis in the input): null')
    return lines


def overbound_lines(exporter, values):
    """Header lines of an overbounding export: what, the horizon, per key factor and tight tau."""
    if values.overbound is None:
        return []
    from ..core.overbound import OVERBOUND_LEVEL
    lines = [f'overbound: the values of this consumer\'s model ({" + ".join(exporter.model)}) '
             f'give an Allan variance at or above the upper {100 * OVERBOUND_LEVEL:g} % bound of '
             f'the measured one at every averaging time from tau0 to the horizon '
             f'{values.horizon_s:.6g} s (imu_allan.core.overbound; Lethander & Taylor 2023); '
             'factors are against the raw fit (its 95 % upper limit where not detected), on '
             'the standard deviations N, K, B (variance keys grow by the square)']
    for key, entry in values.overbound_used.items():
        parts = [f'{axis} x{factor:.3g}' + (
            f' (bound tight at {", ".join(f"{t:.3g}" for t in entry["tight_tau_s"][axis])} s)'
            if entry['tight_tau_s'][axis] else '')
            for axis, factor in entry['factor'].items()]
        lines.append(f'overbound {key}: ' + '; '.join(parts))
    return lines


# ----------------------------------------------------------------------------- writers


def _num(value):
    """Return a float as text PyYAML and OpenCV read as a real (always a dot and an exponent)."""
    return 'null' if value is None else f'{value:.6e}'


def _rate(value):
    return repr(float(value))


def _yaml_lines(data, indent=0):
    """Minimal YAML (block mappings, flow lists) readable by PyYAML and OpenCV FileStorage."""
    pad = ' ' * indent
    lines = []
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f'{pad}{key}:')
            lines += _yaml_lines(value, indent + 2)
        elif isinstance(value, list) and value and isinstance(value[0], list):
            lines.append(f'{pad}{key}:')
            lines += [f'{pad}  - [{", ".join(_num(v) for v in row)}]' for row in value]
        elif isinstance(value, list):
            lines.append(f'{pad}{key}: [{", ".join(_num(v) for v in value)}]')
        elif isinstance(value, bool) or isinstance(value, int):
            lines.append(f'{pad}{key}: {int(value)}')
        elif isinstance(value, str):
            lines.append(f'{pad}{key}: {json.dumps(value)}')
        elif key in ('update_rate', 'IMU.Frequency', 'imu_update_rate', 'SampleRate'):
            lines.append(f'{pad}{key}: {_rate(value)}')
        else:
            lines.append(f'{pad}{key}: {_num(value)}')
    return lines


def _comments(header, marker='#'):
    return [f'{marker} {line}' for line in header]


def _yaml_file(name, opencv=False):
    """Render a dict as YAML with the header; OpenCV files start with ``%YAML:1.0``."""
    def render(data, header, values=None):
        lines = ['%YAML:1.0'] if opencv else []
        lines += _comments(header) + _yaml_lines(data)
        return {name: '\n'.join(lines) + '\n'}
    return render


#: The four numbers most consumers take, in the order :func:`_worst_four` names them.
_FOUR = (('gyro', 'white_noise'), ('gyro', 'rate_random_walk'), ('accel', 'white_noise'),
         ('accel', 'rate_random_walk'))


def _per_step(term, value, rate_hz):
    """N sqrt(f) (white noise, per sample) or K sqrt(f) (a random walk's step over dt)."""
    if term == 'white_noise':
        return discrete_white_std(value, rate_hz)
    return discrete_random_walk_step(value, rate_hz) * rate_hz


def _worst_four(values, keys, convert=None):
    """Worst-axis gyro N, gyro K, accel N, accel K under ``keys`` (``convert(term, value)``)."""
    out = {}
    for key, (sensor, term) in zip(keys, _FOUR):
        value = values.worst(sensor, term, key)
        out[key] = value if value is None or convert is None else convert(term, value)
    return out


# ----------------------------------------------------------------------------- Kalibr


def _kalibr_build(values):
    from .kalibr import kalibr_values
    data, _ = kalibr_values(values)
    data.pop('upper_limits')
    data.pop('inadequate')  # (the header says it, exporter_header)
    return {'rostopic': values.topic, **data}


def _kalibr_render(data, header, values):
    from .kalibr import kalibr_values, kalibr_yaml_text
    return {'kalibr_imu.yaml': kalibr_yaml_text(data, kalibr_values(values)[1], data['rostopic'],
                                                header)}


register(Exporter(
    'kalibr', ('kalibr_imu.yaml',), 'Kalibr (imu.yaml)', 'continuous',
    '*_noise_density = N, *_random_walk = K; Kalibr itself uses N sqrt(f) per sample '
    '(kalibr_common/ConfigReader.py:473,491)',
    _kalibr_build, _kalibr_render))


# ----------------------------------------------------------------------------- OpenVINS

_IDENTITY = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def _openvins_build(values):
    # ov_msckf/src/core/VioManagerOptions.h:159-162 reads these four under imu0;
    # ov_msckf/src/state/Propagator.cpp:463-466 divides by dt (continuous densities).
    imu0 = {'T_i_b': [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0],
                      [0.0, 0.0, 0.0, 1.0]],
            **_worst_four(values, ('gyroscope_noise_density', 'gyroscope_random_walk',
                                   'accelerometer_noise_density', 'accelerometer_random_walk')),
            'rostopic': values.topic, 'time_offset': 0.0, 'update_rate': values.rate_hz,
            'model': 'kalibr', 'Tw': _IDENTITY, 'R_IMUtoGYRO': _IDENTITY, 'Ta': _IDENTITY,
            'R_IMUtoACC': _IDENTITY, 'Tg': [[0.0] * 3 for _ in range(3)]}
    return {'imu0': imu0}


register(Exporter(
    'openvins', ('openvins_imu.yaml',), 'OpenVINS (kalibr_imu_chain.yaml)', 'continuous',
    'noise_density = N, random_walk = K; OpenVINS uses sigma^2/dt per step '
    '(ov_msckf/src/state/Propagator.cpp:463-466)',
    _openvins_build, _yaml_file('openvins_imu.yaml', opencv=True)))


# ----------------------------------------------------------------------------- VINS


def _vins_build(values):
    # vins_estimator/src/factor/integration_base.h: noise = diag(ACC_N^2, GYR_N^2, ACC_N^2,
    # GYR_N^2, ACC_W^2, GYR_W^2) with no dt; V carries 0.5 dt for the two (previous and current
    # sample) white terms and dt for the bias terms.  Per step the angle gets
    # 2 (0.5 dt)^2 GYR_N^2 = 0.5 dt^2 GYR_N^2 (continuous: N^2 dt, so GYR_N = N sqrt(2 f)) and
    # the bias dt^2 GYR_W^2 (continuous: K^2 dt, so GYR_W = K sqrt(f)).
    def per_sample(term, value):
        return _per_step(term, value, values.rate_hz) * (
            math.sqrt(2.0) if term == 'white_noise' else 1.0)
    return {**_worst_four(values, ('gyr_n', 'gyr_w', 'acc_n', 'acc_w'), per_sample),
            'g_norm': STANDARD_GRAVITY, 'imu': 1, 'imu_topic': values.topic}


register(Exporter(
    'vins', ('vins_fusion.yaml',), 'VINS-Fusion / VINS-Mono', 'per sample (discrete sigma)',
    '*_n = N sqrt(2 f) (midpoint integration counts each sample twice with weight 1/2, '
    'vins_estimator/src/factor/integration_base.h), *_w = K sqrt(f) (bias step dt * *_w); '
    'the often-quoted "Kalibr-style" raw N and K are 14x and 10x smaller at 100 Hz',
    _vins_build, _yaml_file('vins_fusion.yaml', opencv=True)))


# ----------------------------------------------------------------------------- ORB-SLAM3


def _orbslam3_build(values):
    # src/Tracking.cc (ParseIMUParamFile, newParameterLoader): sf = sqrt(freq);
    # IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, Naw/sf): the file holds continuous densities.
    return {**_worst_four(values, ('IMU.NoiseGyro', 'IMU.GyroWalk', 'IMU.NoiseAcc',
                                   'IMU.AccWalk')),
            'IMU.Frequency': values.rate_hz}


register(Exporter(
    'orbslam3', ('orbslam3_imu.yaml',), 'ORB-SLAM3 (IMU.* of the settings file)', 'continuous',
    'Noise* = N, *Walk = K; ORB-SLAM3 uses N sqrt(f) per sample and K / sqrt(f) per step '
    '(src/Tracking.cc, IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf, Naw/sf))',
    _orbslam3_build, _yaml_file('orbslam3_imu.yaml', opencv=True)))


# ----------------------------------------------------------------------------- Basalt


def _basalt_build(values):
    # basalt-headers calibration.hpp: dicrete_time_accel_noise_std() = accel_noise_std *
    # sqrt(imu_update_rate); include/basalt/linearization/imu_block.hpp:74-77 weighs the bias
    # residual by 1 / (bias_std sqrt(dt)): continuous densities, per axis.
    calib = {'imu_update_rate': values.rate_hz,
             'accel_noise_std': values.per_axis('accel', 'white_noise', 'accel_noise_std'),
             'gyro_noise_std': values.per_axis('gyro', 'white_noise', 'gyro_noise_std'),
             'accel_bias_std': values.per_axis('accel', 'rate_random_walk', 'accel_bias_std'),
             'gyro_bias_std': values.per_axis('gyro', 'rate_random_walk', 'gyro_bias_std')}
    return {'value0': calib}


def _basalt_render(data, header, values=None):
    out = dict(data)
    out['imu_allan'] = header
    return {'basalt_imu.json': json.dumps(out, indent=2) + '\n'}


register(Exporter(
    'basalt', ('basalt_imu.json',), 'Basalt (calibration JSON)', 'continuous',
    '*_noise_std = N, *_bias_std = K; Basalt uses noise_std sqrt(f) per sample '
    '(basalt-headers calibration.hpp) and bias_std sqrt(dt) per step (imu_block.hpp:74-77)',
    _basalt_build, _basalt_render, per_axis=True))


# ----------------------------------------------------------------------------- GTSAM


def _diag(values3):
    if any(v is None for v in values3):
        return None
    return [[values3[i] if i == j else 0.0 for j in range(3)] for i in range(3)]


#: GTSAM's integrationCovariance is not a sensor property (its examples use 1e-8 I).
GTSAM_INTEGRATION_COVARIANCE = 1e-8


def _gtsam_build(values):
    # gtsam/navigation/ImuFactor.cpp:76-83: B (aCov / dt) B^T, "(1/dt) allows to pass from
    # continuous time noise to discrete time noise"; CombinedImuFactor.cpp:157-178:
    # dt * biasAccCovariance.  Variances (sigma^2) of continuous densities, per axis.
    def cov(sensor, term, key):
        return _diag([None if v is None else v * v for v in values.per_axis(sensor, term, key)])
    return {'gyroscopeCovariance': cov('gyro', 'white_noise', 'gyroscopeCovariance'),
            'accelerometerCovariance': cov('accel', 'white_noise', 'accelerometerCovariance'),
            'biasOmegaCovariance': cov('gyro', 'rate_random_walk', 'biasOmegaCovariance'),
            'biasAccCovariance': cov('accel', 'rate_random_walk', 'biasAccCovariance'),
            'integrationCovariance': _diag([GTSAM_INTEGRATION_COVARIANCE] * 3),
            'gravity': STANDARD_GRAVITY}


_GTSAM_SETTERS = (('gyroscopeCovariance', 'setGyroscopeCovariance'),
                  ('accelerometerCovariance', 'setAccelerometerCovariance'),
                  ('biasOmegaCovariance', 'setBiasOmegaCovariance'),
                  ('biasAccCovariance', 'setBiasAccCovariance'),
                  ('integrationCovariance', 'setIntegrationCovariance'))


def _gtsam_render(data, header, values=None):
    yaml_text = _yaml_file('gtsam_imu.yaml')(data, header)['gtsam_imu.yaml']
    lines = ['r"""GTSAM PreintegrationCombinedParams from imu_allan (run: python gtsam_imu.py).',
             ''] + header + ['', 'Covariances are continuous-time variances (sigma^2), not '
                             'sigma; integrationCovariance', 'is not a sensor property (the '
                             'GTSAM examples use 1e-8 I).', '"""', '',
                             'import gtsam', 'import numpy as np', '',
                             f'params = gtsam.PreintegrationCombinedParams.MakeSharedU('
                             f'{data["gravity"]!r})']
    for key, setter in _GTSAM_SETTERS:
        matrix = data[key]
        if matrix is None:
            lines.append(f'# {key}: not measured')
            continue
        diag = ', '.join(_num(matrix[i][i]) for i in range(3))
        lines.append(f'params.{setter}(np.diag([{diag}]))')
    lines += ['', "if __name__ == '__main__':", '    print(params)']
    return {'gtsam_imu.yaml': yaml_text, 'gtsam_imu.py': '\n'.join(lines) + '\n'}


register(Exporter(
    'gtsam', ('gtsam_imu.yaml', 'gtsam_imu.py'), 'GTSAM (PreintegrationCombinedParams)',
    'continuous', 'covariance = N^2 I and K^2 I per axis (variances); GTSAM divides by dt '
    '(gtsam/navigation/ImuFactor.cpp:76-83, CombinedImuFactor.cpp:157-178)',
    _gtsam_build, _gtsam_render, per_axis=True))


# ----------------------------------------------------------------------------- LIO-SAM


def _lio_sam_build(values):
    # src/imuPreintegration.cpp:214-217: accelerometerCovariance = imuAccNoise^2 I ("acc white
    # noise in continuous"); :225, :374-375: bias BetweenFactor sigma sqrt(deltaTij) *
    # imuAccBiasN: continuous densities.
    params = {**_worst_four(values, ('imuGyrNoise', 'imuGyrBiasN', 'imuAccNoise', 'imuAccBiasN')),
              'imuGravity': STANDARD_GRAVITY}
    return {'/**': {'ros__parameters': params}}


register(Exporter(
    'lio_sam', ('lio_sam_imu.yaml',), 'LIO-SAM (params.yaml, ros2 branch layout)', 'continuous',
    'imu*Noise = N, imu*BiasN = K, through GTSAM (src/imuPreintegration.cpp:214-217, 225); '
    'ROS 1 users put the same keys under "lio_sam:"',
    _lio_sam_build, _yaml_file('lio_sam_imu.yaml')))


# ----------------------------------------------------------------------------- FAST-LIO


def _fast_lio_build(values):
    # src/IMU_Processing.hpp:280-284 puts the values on the diagonal of Q; IKFoM
    # esekfom.hpp:381: P = F P F^T + (dt f_w) Q (dt f_w)^T, so per step the velocity gets
    # dt^2 acc_cov (continuous: N^2 dt -> acc_cov = N^2 f) and the bias dt^2 b_acc_cov
    # (continuous: K^2 dt -> b_acc_cov = K^2 f): per-sample variances.
    mapping = _worst_four(values, ('gyr_cov', 'b_gyr_cov', 'acc_cov', 'b_acc_cov'),
                          lambda term, value: _per_step(term, value, values.rate_hz) ** 2)
    return {'/**': {'ros__parameters': {'mapping': mapping}}}


register(Exporter(
    'fast_lio', ('fast_lio_imu.yaml',), 'FAST-LIO (mapping.*, ROS2 branch layout)',
    'per sample (discrete variances)',
    '*_cov = N^2 f, b_*_cov = K^2 f ((m/s^2)^2, (rad/s)^2; src/IMU_Processing.hpp:280-284 and '
    'IKFoM esekfom.hpp:381 multiply by dt^2 per step)',
    _fast_lio_build, _yaml_file('fast_lio_imu.yaml')))


# ----------------------------------------------------------------------------- MATLAB


#: MATLAB's gyroparams / accelparams keys and the term each holds.
_MATLAB_KEYS = (('NoiseDensity', 'white_noise'), ('RandomWalk', 'rate_random_walk'),
                ('BiasInstability', 'bias_instability'))


def _matlab_build(values):
    # gyroparams / accelparams: NoiseDensity (rad/s)/sqrt(Hz) = N, RandomWalk (rad/s)*sqrt(Hz)
    # = K (MathWorks answer 1631045), BiasInstability rad/s = B, as MathWorks' example
    # "Inertial Sensor Noise Analysis Using Allan Variance" reads them off allanvar.
    out = {'SampleRate': values.rate_hz}
    for sensor, name in (('gyro', 'gyroparams'), ('accel', 'accelparams')):
        out[name] = {key: values.per_axis(sensor, term, f'{name}.{key}')
                     for key, term in _MATLAB_KEYS}
        gm = {}
        for axis in values.axes(sensor):
            sigma, _ = values.value(axis, 'gauss_markov', 'sigma')
            if math.isfinite(sigma):
                gm[axis] = {'sigma': sigma, 'tau_c': values.value(axis, 'gauss_markov',
                                                                  'tau_c')[0]}
        if gm:
            out[name]['gauss_markov'] = gm
    return out


def _matlab_vector(values3):
    return '[' + ' '.join('NaN' if v is None else _num(v) for v in values3) + ']'


def _matlab_render(data, header, values=None):
    lines = _comments(header, '%') + [
        '% NoiseDensity = N, RandomWalk = K (rate random walk), BiasInstability = B: the reading',
        '% of MathWorks\' example "Inertial Sensor Noise Analysis Using Allan Variance".',
        '% Check the NoiseType convention of your release (default "double-sided").',
        f'fs = {_rate(data["SampleRate"])};']
    for name, var in (('gyroparams', 'gyro'), ('accelparams', 'accel')):
        params = data[name]
        args = ', '.join(f"'{key}', {_matlab_vector(params[key])}" for key, _ in _MATLAB_KEYS)
        lines.append(f'{var} = {name}({args});')
        for axis, gm in params.get('gauss_markov', {}).items():
            phi = math.exp(-1.0 / (data['SampleRate'] * gm['tau_c']))
            lines.append(f'% {axis}: fitted first-order Gauss-Markov sigma {_num(gm["sigma"])}, '
                         f'tau_c {gm["tau_c"]:.6g} s; R2023b+: BiasInstability = sigma with '
                         f"BiasInstabilityCoefficients = struct('Numerator', "
                         f"{math.sqrt(1 - phi * phi):.6e}, 'Denominator', [1 {-phi:.9f}])")
    lines.append("imu = imuSensor('accel-gyro', 'SampleRate', fs, 'Gyroscope', gyro, "
                 "'Accelerometer', accel);")
    return {'matlab_imu.m': '\n'.join(lines) + '\n'}


register(Exporter(
    'matlab', ('matlab_imu.m',), 'MATLAB Navigation / Sensor Fusion Toolbox (imuSensor)',
    'continuous', 'NoiseDensity = N, RandomWalk = K, BiasInstability = B, per axis',
    _matlab_build, _matlab_render, per_axis=True,
    model=('white_noise', 'bias_instability', 'rate_random_walk')))


# ----------------------------------------------------------------------------- API


def _overbound_fits(fitted, exports):
    """Return the overbounds of ``exports`` (:class:`ExportOptions`) of a fit; None: raw."""
    if exports.horizon_s is not None and not exports.overbound:
        raise ValueError('horizon_s is only used with overbound=True')
    if not exports.overbound:
        return None
    from ..core.record import overbound_values
    return overbound_values(fitted, replace(exports.overbound_request(), consumers=()))


def export(fitted, name, rate_hz=None, inflate=1.0, source=None, topic='/imu/data_raw',
           overbound=False, horizon_s=None):
    """
    Return the data one exporter writes, as a dict (SI; time base as the consumer wants it).

    ``fitted`` is a FittedModel (from :func:`imu_allan.fit_noise_model`) or an Analysis;
    ``rate_hz`` the IMU rate the consumer runs at (default: the rate of the fit);
    ``inflate`` a factor or ``(white, walk)`` on the standard deviations (on top of the
    overbound); ``overbound=True``: the values of the consumer's own model whose Allan variance
    is at or above the measured upper 95 % bound from tau0 to ``horizon_s`` (default: the
    longest measured averaging time; :mod:`imu_allan.core.overbound`).
    """
    exporter = exporter_of(name)
    fits = _overbound_fits(fitted, ExportOptions((name,), inflate, overbound, horizon_s))
    return exporter.build(ExportValues(fitted, rate_hz, inflate, source, topic, fits,
                                       exporter.model))


def write_exports(folder, fitted, exports, source=None, topic='/imu/data_raw', fits=None,
                  rate_hz=None):
    """
    Write the exporters of ``exports`` (:class:`ExportOptions`) into ``folder/export/``.

    Returns the files' paths relative to ``folder``.  ``fits``: the overbounding values
    computed with the record (:class:`~imu_allan.core.record.OverboundValues`), else (with
    ``exports.overbound``) fitted here; an overbound that cannot be made raises its
    :class:`~imu_allan.core.overbound.OverboundError` (an InputError naming the option).
    """
    exporters = [exporter_of(n) for n in exports.names]
    if fits is None:
        fits = _overbound_fits(fitted, exports)
    target = Path(folder) / EXPORT_DIR
    target.mkdir(parents=True, exist_ok=True)
    written = []
    for exporter in exporters:
        values = ExportValues(fitted, rate_hz, exports.inflate, source, topic,
                              fits if exports.overbound else None, exporter.model)
        data = exporter.build(values)
        for file_name, text in exporter.render(data, header_lines(exporter, values),
                                               values).items():
            (target / file_name).write_text(text, encoding='utf-8')
            written.append(f'{EXPORT_DIR}/{file_name}')
    return written


# The simulators' formats (Gazebo, PX4) come last in the registry, after the estimators'.
for _exporter in SIM_EXPORTERS:
    register(_exporter)
