"""
Every exporter's file, read back through that consumer's own noise propagation.

For each exporter the file is written from a fitted model, its TEXT is parsed (YAML, JSON, the
MATLAB ``.m`` and the GTSAM ``.py``), its numbers are turned into the noise the consumer itself
propagates (re-implemented from the consumer's source, cited in each ``_noise_*`` function),
samples are generated from that noise and their Allan deviation (``imu_allan.allan_deviation``)
must lie in the 68 % band of the fitted model where white noise or rate random walk dominates.

Model: white noise N and rate random walk K (crossover near 17 s), the z gyro and the y
accelerometer 1.5 times noisier than the other axes, so the worst-axis rule is exercised;
30 min at 100 Hz, fitted with both terms (fixed selection: fast, and both are detected).

Tolerance, and why it is fair: a point passes when the 68.3 % interval of the generated
record's deviation overlaps the fitted model's 68.3 % band (the model evaluated at the ends of
the fitted N and K intervals).  Both are 1-sigma statements about the same quantity, so a
correct conversion passes with high probability at every point; the points checked are those
where white noise carries >= 95 % or the random walk >= 90 % of the model variance.  At
tau <= 0.1 s both intervals are < 1 % wide, so a factor sqrt(2) (VINS' midpoint rule) or
sqrt(f) = 10 fails by tens of sigma (``test_wrong_conversion_fails`` checks the 10x).  The
generators use the same seed for every consumer, so correct files give the same series.
Budget: about 15 s of CPU for the whole file on an idle machine (one 30-min fit, 9 exporters x
2-6 generated axes, three ``analyze`` runs).
"""

import ast
import copy
import json
import math
import re
import runpy
import subprocess
import sys

from conftest import run_command
import imu_allan
from imu_allan.core.allan.edf import chi2_interval
from imu_allan.core.model import NoiseModel
from imu_allan.core.overbound import upper_bound
from imu_allan.core.record import overbound_values
from imu_allan.core.simulation.simulate import flicker_noise
from imu_allan.errors import InputError
from imu_allan.report.exporters import export, EXPORTERS, ExportOptions, write_exports
import numpy as np
import pytest
import yaml

RATE = 100.0
N_SAMPLES = 180_000  # 30 min
SEED = 2024
GYRO_N, GYRO_K = 1e-3, 1e-4    # rad/s/sqrt(Hz), rad/s^2/sqrt(Hz)
ACCEL_N, ACCEL_K = 2e-3, 2e-4  # m/s^2/sqrt(Hz), m/s^3/sqrt(Hz)
WORST = {'gyro': 'gyro_z', 'accel': 'accel_y'}


@pytest.fixture(scope='module')
def fitted():
    truth = NoiseModel.from_dict({
        'gyro': {'white_noise': GYRO_N, 'rate_random_walk': GYRO_K},
        'accel': {'white_noise': ACCEL_N, 'rate_random_walk': ACCEL_K},
        'axes': {'gyro_z': {'white_noise': 1.5 * GYRO_N, 'rate_random_walk': 1.5 * GYRO_K},
                 'accel_y': {'white_noise': 1.5 * ACCEL_N,
                             'rate_random_walk': 1.5 * ACCEL_K}}})
    data = imu_allan.simulate(truth, N_SAMPLES, RATE, seed=1)
    result = imu_allan.allan_deviation(data, RATE)
    return imu_allan.fit_noise_model(result, terms=['white_noise', 'rate_random_walk'])


@pytest.fixture(scope='module')
def files(fitted, tmp_path_factory):
    folder = tmp_path_factory.mktemp('exports')
    written = write_exports(folder, fitted, ExportOptions(tuple(EXPORTERS)),
                            source='simulated test record')
    return {p.split('/')[-1]: (folder / p).read_text() for p in written}


# --------------------------------------------------------------------------- parsing


def _opencv_yaml(text):
    """Parse OpenCV FileStorage YAML: drop the ``%YAML:1.0`` directive PyYAML refuses."""
    assert text.startswith('%YAML:1.0\n')
    return yaml.safe_load(text.split('\n', 1)[1])


def _gtsam_py(text):
    """Return the variances set in the GTSAM snippet: {setter: [x, y, z]} (parsed, not run)."""
    out = {}
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, ast.Call) and getattr(node.func, 'attr', '').startswith('set'):
            diag = node.args[0]
            assert getattr(diag.func, 'attr', '') == 'diag'
            out[node.func.attr] = ast.literal_eval(diag.args[0])
    return out


def _matlab(text):
    """``fs`` and the gyroparams / accelparams name-value vectors of the ``.m`` file."""
    fs = float(re.search(r'^fs = ([^;]+);', text, re.M).group(1))
    out = {'fs': fs}
    for var, cls in (('gyro', 'gyroparams'), ('accel', 'accelparams')):
        call = re.search(rf'^{var} = {cls}\((.*)\);$', text, re.M).group(1)
        out[var] = {k: [float(v) for v in vec.split()]
                    for k, vec in re.findall(r"'(\w+)', \[([^\]]*)\]", call)}
    return out


# --------------------------------------------------------------------------- consumers
# Each returns {axis: (white std per sample, bias step std per sample, midpoint)} for the axes
# the file describes, from the consumer's own reading of its keys at sample period dt.

def _axes_worst():
    return list(WORST.values())


def _noise_kalibr(files):
    """
    Kalibr: the noise its own propagation adds, from its keys.

    Kalibr: ConfigReader.py:473,491 sigma_d = N / sqrt(1/update_rate) per sample; the bias
    is a continuous random walk of strength K (IccSensors.py:768-773), K sqrt(dt) per sample.
    """
    k = yaml.safe_load(files['kalibr_imu.yaml'])
    dt = 1.0 / k['update_rate']
    return {'gyro_z': (k['gyroscope_noise_density'] / math.sqrt(dt),
                       k['gyroscope_random_walk'] * math.sqrt(dt), False),
            'accel_y': (k['accelerometer_noise_density'] / math.sqrt(dt),
                        k['accelerometer_random_walk'] * math.sqrt(dt), False)}


def _noise_openvins(files):
    """
    OpenVINS: the noise its own propagation adds, from its keys.

    OpenVINS ov_msckf/src/state/Propagator.cpp:225-228: sigma_w^2 / dt for white noise,
    sigma_wb^2 dt per step for the bias (same continuous reading as Kalibr).
    """
    imu = _opencv_yaml(files['openvins_imu.yaml'])['imu0']
    dt = 1.0 / imu['update_rate']
    assert imu['model'] == 'kalibr' and np.allclose(imu['Tw'], np.eye(3))
    return {'gyro_z': (math.sqrt(imu['gyroscope_noise_density'] ** 2 / dt),
                       math.sqrt(imu['gyroscope_random_walk'] ** 2 * dt), False),
            'accel_y': (math.sqrt(imu['accelerometer_noise_density'] ** 2 / dt),
                        math.sqrt(imu['accelerometer_random_walk'] ** 2 * dt), False)}


def _noise_vins(files, text=None):
    """
    VINS-Fusion: the noise its own propagation adds, from its keys.

    VINS-Fusion vins_estimator/src/factor/integration_base.h: noise = diag(ACC_N^2, GYR_N^2,
    ACC_N^2, GYR_N^2, ACC_W^2, GYR_W^2) with no dt; V = 0.5 dt for the previous and the current
    sample's white terms (midpoint), dt for the bias terms.  So each step integrates
    0.5 (n0 + n1) with n0, n1 ~ N(0, GYR_N^2) independent, and the bias steps by dt GYR_W.
    """
    v = _opencv_yaml(text or files['vins_fusion.yaml'])
    dt = 1.0 / RATE  # VINS takes dt from the message stamps
    return {'gyro_z': (v['gyr_n'], v['gyr_w'] * dt, True),
            'accel_y': (v['acc_n'], v['acc_w'] * dt, True)}


def _noise_orbslam3(files):
    """
    ORB-SLAM3: the noise its own propagation adds, from its keys.

    ORB-SLAM3 src/Tracking.cc: sf = sqrt(freq); IMU::Calib(Tbc, Ng*sf, Na*sf, Ngw/sf,
    Naw/sf); src/ImuTypes.cc IntegrateNewMeasurement adds the walk covariance once per sample.
    """
    o = _opencv_yaml(files['orbslam3_imu.yaml'])
    sf = math.sqrt(o['IMU.Frequency'])
    return {'gyro_z': (o['IMU.NoiseGyro'] * sf, o['IMU.GyroWalk'] / sf, False),
            'accel_y': (o['IMU.NoiseAcc'] * sf, o['IMU.AccWalk'] / sf, False)}


def _noise_basalt(files):
    """
    Basalt: the noise its own propagation adds, from its keys.

    Basalt: basalt-headers calibration.hpp dicrete_time_*_noise_std = std sqrt(rate);
    include/basalt/linearization/imu_block.hpp:74-77 bias weight 1 / (bias_std sqrt(dt)).
    """
    c = json.loads(files['basalt_imu.json'])['value0']
    r = c['imu_update_rate']
    out = {}
    for sensor, prefix in (('gyro', 'gyro'), ('accel', 'accel')):
        for i, axis in enumerate(f'{sensor}_{a}' for a in 'xyz'):
            out[axis] = (c[f'{prefix}_noise_std'][i] * math.sqrt(r),
                         c[f'{prefix}_bias_std'][i] / math.sqrt(r), False)
    return out


def _noise_gtsam(files):
    """
    GTSAM: the noise its own propagation adds, from its keys.

    GTSAM gtsam/navigation/ImuFactor.cpp:76-83 (aCov / dt) per sample and
    CombinedImuFactor.cpp:157-178 dt * biasAccCovariance per step, from the snippet's text.
    """
    py = _gtsam_py(files['gtsam_imu.py'])
    y = yaml.safe_load(files['gtsam_imu.yaml'])
    assert np.allclose(np.diag(y['gyroscopeCovariance']), py['setGyroscopeCovariance'])
    dt = 1.0 / RATE
    out = {}
    for sensor, white, bias in (('gyro', 'setGyroscopeCovariance', 'setBiasOmegaCovariance'),
                                ('accel', 'setAccelerometerCovariance', 'setBiasAccCovariance')):
        for i, axis in enumerate(f'{sensor}_{a}' for a in 'xyz'):
            out[axis] = (math.sqrt(py[white][i] / dt), math.sqrt(py[bias][i] * dt), False)
    return out


def _noise_lio_sam(files):
    """
    LIO-SAM: the noise its own propagation adds, from its keys.

    LIO-SAM src/imuPreintegration.cpp:214-217 covariance = imu*Noise^2 handed to GTSAM
    (divided by dt per sample); :225, :374-375 bias BetweenFactor sigma sqrt(dt) imu*BiasN.
    """
    p = yaml.safe_load(files['lio_sam_imu.yaml'])['/**']['ros__parameters']
    dt = 1.0 / RATE
    return {'gyro_z': (math.sqrt(p['imuGyrNoise'] ** 2 / dt), p['imuGyrBiasN'] * math.sqrt(dt),
                       False),
            'accel_y': (math.sqrt(p['imuAccNoise'] ** 2 / dt),
                        p['imuAccBiasN'] * math.sqrt(dt), False)}


def _noise_fast_lio(files, text=None):
    """
    FAST-LIO: the noise its own propagation adds, from its keys.

    FAST-LIO src/IMU_Processing.hpp:280-284 Q = diag(cov); IKFoM esekfom.hpp:381
    P += (dt f_w) Q (dt f_w)^T: the rate noise has variance acc_cov per sample, the bias steps
    with variance dt^2 b_acc_cov.
    """
    m = yaml.safe_load(text or files['fast_lio_imu.yaml'])['/**']['ros__parameters']['mapping']
    dt = 1.0 / RATE
    return {'gyro_z': (math.sqrt(m['gyr_cov']), dt * math.sqrt(m['b_gyr_cov']), False),
            'accel_y': (math.sqrt(m['acc_cov']), dt * math.sqrt(m['b_acc_cov']), False)}


def _noise_matlab(files):
    """
    MATLAB: the noise its own propagation adds, from its keys.

    MATLAB imuSensor with gyroparams/accelparams read as in MathWorks' example "Inertial
    Sensor Noise Analysis Using Allan Variance" (NoiseDensity = N, RandomWalk = K): N sqrt(fs)
    per sample, K / sqrt(fs) per step.  imuSensor's code is closed, so this follows its docs;
    BiasInstability (written here as an upper limit) is not simulated.
    """
    m = _matlab(files['matlab_imu.m'])
    fs = m['fs']
    out = {}
    for sensor in ('gyro', 'accel'):
        for i, axis in enumerate(f'{sensor}_{a}' for a in 'xyz'):
            out[axis] = (m[sensor]['NoiseDensity'][i] * math.sqrt(fs),
                         m[sensor]['RandomWalk'][i] / math.sqrt(fs), False)
    return out


CONSUMERS = {'kalibr': _noise_kalibr, 'openvins': _noise_openvins, 'vins': _noise_vins,
             'orbslam3': _noise_orbslam3, 'basalt': _noise_basalt, 'gtsam': _noise_gtsam,
             'lio_sam': _noise_lio_sam, 'fast_lio': _noise_fast_lio, 'matlab': _noise_matlab}


def _generate(noise, n=N_SAMPLES, seed=SEED):
    """Return samples per axis from (white std, bias step std, midpoint) with one seed per axis."""
    axes = sorted(noise)
    data = np.empty((n, len(axes)))
    for j, axis in enumerate(axes):
        white, step, midpoint = noise[axis]
        rng = np.random.default_rng([seed, j])
        w = rng.standard_normal(n)
        if midpoint:  # VINS takes the two half-weighted white terms of a step as independent
            w = 0.5 * (w + rng.standard_normal(n))
        data[:, j] = white * w + np.cumsum(step * rng.standard_normal(n))
    return axes, data


def _band_scores(fitted, axes, data):
    """
    Mean distance of the generated deviation from the fitted model, in 68 % band units.

    For each axis and regime (``'white'``: white noise >= 95 % of the model variance,
    ``'walk'``: rate random walk >= 90 %), the mean over those averaging times of
    ``log(adev / model) / s``, where ``s`` combines the half-widths (in log) of the fitted
    model's 68 % band (the model at the ends of the N and K intervals) and of the generated
    record's own 68 % interval.  Also returns the median ratio adev / model over the white
    points of each axis.
    """
    result = imu_allan.allan_deviation(data, RATE)
    tau = result.tau
    scores, ratios = {}, {}
    for j, axis in enumerate(axes):
        n, k = fitted.value(axis, 'white_noise'), fitted.value(axis, 'rate_random_walk')
        (n_lo, n_hi), (k_lo, k_hi) = (fitted.interval(axis, 'white_noise'),
                                      fitted.interval(axis, 'rate_random_walk'))
        total = fitted.model_avar(axis, tau)
        white = n * n / tau
        walk = total - white
        lo = np.sqrt(n_lo ** 2 / tau + walk * (k_lo / k) ** 2)
        hi = np.sqrt(n_hi ** 2 / tau + walk * (k_hi / k) ** 2)
        s = np.hypot(0.5 * np.log(hi / lo),
                     0.5 * np.log(result.ci_high[:, j] / result.ci_low[:, j]))
        z = np.log(result.adev[:, j] / np.sqrt(total)) / s
        for regime, points in (('white', white >= 0.95 * total), ('walk', walk >= 0.90 * total)):
            assert points.sum() >= 2, (axis, regime)
            scores[axis, regime] = float(np.mean(z[points]))
        ratios[axis] = float(np.median(result.adev[white >= 0.95 * total, j]
                                       / np.sqrt(total[white >= 0.95 * total])))
    return scores, ratios


def _misses(scores, limit=3.0):
    return [f'{axis} {regime}: {z:+.2f}' for (axis, regime), z in scores.items()
            if not abs(z) <= limit]


# --------------------------------------------------------------------------- tests


@pytest.mark.parametrize('name', sorted(CONSUMERS))
def test_consumer_reproduces_the_fitted_allan_deviation(name, fitted, files):
    noise = CONSUMERS[name](files)
    assert set(_axes_worst()) <= set(noise)
    scores, ratios = _band_scores(fitted, *_generate(noise))
    assert not _misses(scores), f'{name}: ' + '; '.join(_misses(scores))
    assert np.allclose(list(ratios.values()), 1.0, rtol=0.02)


def test_wrong_conversion_fails(fitted, files):
    """
    Deliberately wrong conversions must fail the same check.

    A missing sqrt(f) (FAST-LIO variances not multiplied by f) is 10x off at 100 Hz, and
    raw Kalibr-style numbers in the VINS file are sqrt(2 f) = 14x off: the check must fail.
    """
    text = files['fast_lio_imu.yaml']
    data = yaml.safe_load(text)['/**']['ros__parameters']['mapping']
    wrong = text
    for key in ('acc_cov', 'gyr_cov'):
        wrong = wrong.replace(f'{key}: {data[key]:.6e}', f'{key}: {data[key] / RATE:.6e}')
    assert wrong != text
    scores, ratios = _band_scores(fitted, *_generate(_noise_fast_lio(files, wrong)))
    assert {(a, r) for a, r in scores if abs(scores[a, r]) > 3} == {('gyro_z', 'white'),
                                                                    ('accel_y', 'white')}
    assert np.allclose(list(ratios.values()), 1.0 / math.sqrt(RATE), rtol=0.1)

    kalibr = yaml.safe_load(files['kalibr_imu.yaml'])
    v = _opencv_yaml(files['vins_fusion.yaml'])
    raw = files['vins_fusion.yaml']
    for key, kal in (('gyr_n', 'gyroscope_noise_density'),
                     ('acc_n', 'accelerometer_noise_density')):
        raw = raw.replace(f'{key}: {v[key]:.6e}', f'{key}: {kalibr[kal]:.6e}')
    scores, ratios = _band_scores(fitted, *_generate(_noise_vins(files, raw)))
    assert _misses(scores)
    assert np.allclose(list(ratios.values()), 1.0 / math.sqrt(2 * RATE), rtol=0.1)


def test_every_file_has_the_header(files):
    assert sorted(files) == sorted(f for e in EXPORTERS.values() for f in e.files)
    for name, text in files.items():
        head = text[:1500]
        assert f'imu_allan {imu_allan.__version__}' in head, name
        assert 'input: simulated test record' in head and 'rate: 100 Hz' in head, name
        assert 'time base:' in head and 'inflation: none' in head, name
        assert ('worst (largest) axis per sensor' in head) != ('per axis (x, y, z)' in head)
    assert 'gyr_n from gyro_z' in files['vins_fusion.yaml']
    assert 'acc_cov from accel_y' in files['fast_lio_imu.yaml']
    # the fit selected no bias instability: MATLAB gets its 95 % upper limit, marked
    assert re.search(r'gyroparams.BiasInstability: not detected on gyro_x, gyro_y, gyro_z',
                     files['matlab_imu.m'])
    meta = json.loads(files['basalt_imu.json'])['imu_allan']
    assert any('per axis' in line for line in meta)
    compile(files['gtsam_imu.py'], 'gtsam_imu.py', 'exec')


def test_export_api_inflation_and_upper_limits(fitted):
    assert imu_allan.export is export  # the lazy top-level API entry
    plain = export(fitted, 'fast_lio', RATE)['/**']['ros__parameters']['mapping']
    inflated = export(fitted, 'fast_lio', RATE, inflate=(2, 10))['/**']['ros__parameters']
    assert inflated['mapping']['acc_cov'] == pytest.approx(4 * plain['acc_cov'])
    assert inflated['mapping']['b_gyr_cov'] == pytest.approx(100 * plain['b_gyr_cov'])
    n = fitted.value('gyro_z', 'white_noise')
    assert plain['gyr_cov'] == pytest.approx(n * n * RATE)
    assert export(fitted, 'vins', RATE)['gyr_n'] == pytest.approx(n * math.sqrt(2 * RATE))
    assert export(fitted, 'kalibr', 200.0)['update_rate'] == 200.0
    basalt = export(fitted, 'basalt')['value0']
    assert basalt['gyro_noise_std'][0] == pytest.approx(fitted.value('gyro_x', 'white_noise'))
    matlab = export(fitted, 'matlab')['gyroparams']
    assert all(b > 0 for b in matlab['BiasInstability'])  # upper limits, not zeros
    with pytest.raises(ValueError, match='unknown exporter'):
        export(fitted, 'nosuch')
    with pytest.raises(ValueError, match='> 0'):
        export(fitted, 'vins', inflate=0)


def test_white_only_gyro_marks_upper_limits_and_missing_sensor():
    data = imu_allan.simulate({'gyro': {'white_noise': GYRO_N}}, 30_000, RATE, seed=3)
    fit = imu_allan.fit_noise_model(imu_allan.allan_deviation(data, RATE),
                                    terms=['white_noise'])
    out = export(fit, 'vins')
    assert out['gyr_w'] > 0 and out['acc_n'] is None


@pytest.mark.slow
@pytest.mark.ros
def test_cli_writes_every_export_and_rejects_bad_names(tmp_path):
    data = imu_allan.simulate({'gyro': {'white_noise': GYRO_N, 'rate_random_walk': GYRO_K},
                               'accel': {'white_noise': ACCEL_N}}, 30_000, RATE, seed=5)
    csv = tmp_path / 'sim.csv'
    t = np.arange(data.shape[0]) / RATE
    np.savetxt(csv, np.column_stack([t, data]), delimiter=',', comments='',
               header='t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z')
    out = tmp_path / 'report'
    proc = run_command('analyze', csv, '--out', out, '--export', 'all', '--inflate', '2,10',
                       '--terms', 'white_noise,rate_random_walk', '--quiet')
    assert proc.returncode == 0, proc.stderr
    written = sorted(p.name for p in (out / 'export').iterdir())
    assert written == sorted(f for e in EXPORTERS.values() for f in e.files)
    for path in (out / 'export').iterdir():
        assert 'white noise x2, bias (random walk, instability) x10' in path.read_text()
    for args, word in ((('--export', 'kalibr,nosuch'), 'nosuch'), (('--export', 'vins',
                                                                    '--inflate', '0'),
                                                                   '--inflate')):
        proc = run_command('analyze', csv, '--out', tmp_path / 'bad', *args, '--quiet')
        assert proc.returncode == 2 and word in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1
        assert not (tmp_path / 'bad').exists()


# --------------------------------------------------------------------------- overbound


@pytest.fixture(scope='module')
def overbound_files(fitted, tmp_path_factory):
    folder = tmp_path_factory.mktemp('overbound')
    request = ExportOptions(tuple(EXPORTERS), overbound=True).overbound_request()
    fits = overbound_values(fitted, request)
    summary = fits.block
    written = write_exports(folder, fitted, ExportOptions(tuple(EXPORTERS), overbound=True),
                            source='simulated test record', fits=fits)
    return {p.split('/')[-1]: (folder / p).read_text() for p in written}, summary


def _matlab_flicker(files, axes, data):
    """Add MATLAB's BiasInstability (in its model, overbounded too) as 1/f noise of that B."""
    m = _matlab(files['matlab_imu.m'])
    for j, axis in enumerate(axes):
        sensor, i = axis.split('_')[0], 'xyz'.index(axis[-1])
        rng = np.random.default_rng([SEED, 100 + j])
        data[:, j] += flicker_noise(rng, data.shape[0], RATE, m[sensor]['BiasInstability'][i])
    return data


def _below_bound(fitted, name, axes, data):
    """Averaging times (<= horizon) where the generated deviation's 3-sigma top is below it."""
    res = fitted.result
    gen = imu_allan.allan_deviation(data, RATE, axes=axes)
    assert np.allclose(gen.tau, res.tau)
    _, top = chi2_interval(gen.adev, gen.edf, level=0.9973)
    misses = []
    for j, axis in enumerate(axes):
        bounded = [axis] if EXPORTERS[name].per_axis else [
            a for a in fitted.axes if a.split('_')[0] == axis.split('_')[0]]
        tau, bound, _ = upper_bound(res, bounded)
        low = top[:tau.size, j] < np.sqrt(bound)
        misses += [f'{axis} at {t:.3g} s' for t in tau[low]]
    return misses


@pytest.mark.parametrize('name', sorted(CONSUMERS))
def test_consumer_keeps_the_overbound(name, fitted, overbound_files):
    """
    Samples drawn from an --overbound file (the consumer's own conversion) stay above the bound.

    The bound is the measured upper 95 % Allan deviation (the envelope of the sensor's axes
    where the file has one number per sensor), up to the horizon (the longest measured tau).
    Tolerance: the generated record's own 99.73 % (3-sigma) upper end must reach the bound at
    every averaging time; where the bound is tight the model equals it, so a correct file
    misses with about 0.13 % probability per point, while a conversion off by sqrt(2)
    (VINS' midpoint) or more misses by tens of sigma at the short averaging times.
    """
    files, summary = overbound_files
    axes, data = _generate(CONSUMERS[name](files))
    if name == 'matlab':
        data = _matlab_flicker(files, axes, data)
    assert not _below_bound(fitted, name, axes, data)
    assert summary['exports'][name]
    assert summary['horizon_s'] == pytest.approx(fitted.result.tau[-1])
    for key, entry in summary['exports'][name].items():
        assert all(f > 0 for f in entry['factor'].values()), (key, entry)
        assert all(entry['tight_tau_s'].values()), (key, entry)


def test_raw_and_misread_overbound_files_fall_below(fitted, files, overbound_files):
    """The same check fails for the raw VINS file and for the overbound one read as Kalibr's."""
    axes, data = _generate(_noise_vins(files))
    assert _below_bound(fitted, 'vins', axes, data)
    ob = overbound_files[0]['vins_fusion.yaml']
    v = _opencv_yaml(ob)
    for key in ('gyr_n', 'acc_n'):
        ob = ob.replace(f'{key}: {v[key]:.6e}', f'{key}: {v[key] / math.sqrt(2.0):.6e}')
    axes, data = _generate(_noise_vins(files, ob))
    assert _below_bound(fitted, 'vins', axes, data)


def test_overbound_headers_and_api(fitted, overbound_files):
    files, summary = overbound_files
    assert summary['level'] == 0.95 and summary['inflate'] == [1.0, 1.0]
    for name, text in files.items():
        head = text[:4000]
        assert 'overbound: the values of this consumer' in head, name
        assert 'to the horizon' in head and 'against the raw fit' in head, name
        assert re.search(r'overbound \S+: \S+ x[0-9.]+ \(bound tight at ', head), name
    data = export(fitted, 'kalibr', RATE, overbound=True)
    assert data['gyroscope_noise_density'] == pytest.approx(
        yaml.safe_load(files['kalibr_imu.yaml'])['gyroscope_noise_density'], rel=1e-6)
    # --inflate multiplies on top, and says so
    inflated = export(fitted, 'kalibr', RATE, inflate=(2, 3), overbound=True)
    assert inflated['gyroscope_noise_density'] == pytest.approx(
        2 * data['gyroscope_noise_density'])
    assert inflated['gyroscope_random_walk'] == pytest.approx(3 * data['gyroscope_random_walk'])
    # a shorter horizon bounds fewer averaging times: never larger N and K together
    short = export(fitted, 'kalibr', RATE, overbound=True, horizon_s=1.0)
    assert (short['gyroscope_noise_density'], short['gyroscope_random_walk']) != (
        data['gyroscope_noise_density'], data['gyroscope_random_walk'])
    with pytest.raises(ValueError, match='horizon'):
        export(fitted, 'kalibr', RATE, overbound=True, horizon_s=1e6)
    with pytest.raises(ValueError, match='overbound=True'):
        export(fitted, 'kalibr', RATE, horizon_s=10.0)


def test_gtsam_snippet_runs(files, tmp_path):
    """The generated gtsam_imu.py runs in real GTSAM and holds the YAML's covariances."""
    gtsam = pytest.importorskip('gtsam')
    path = tmp_path / 'gtsam_imu.py'
    path.write_text(files['gtsam_imu.py'])
    params = runpy.run_path(str(path), run_name='snippet')['params']
    assert isinstance(params, gtsam.PreintegrationCombinedParams)
    data = yaml.safe_load(files['gtsam_imu.yaml'])
    for key in ('gyroscopeCovariance', 'accelerometerCovariance', 'biasOmegaCovariance',
                'biasAccCovariance', 'integrationCovariance'):
        getter = getattr(params, 'get' + key[0].upper() + key[1:])
        np.testing.assert_allclose(getter(), data[key], rtol=1e-6)
    np.testing.assert_allclose(params.n_gravity, [0.0, 0.0, -data['gravity']])
    proc = subprocess.run([sys.executable, str(path)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and 'gyroscopeCovariance' in proc.stdout, proc.stderr


@pytest.mark.slow
@pytest.mark.ros
def test_cli_overbound(tmp_path):
    data = imu_allan.simulate({'gyro': {'white_noise': GYRO_N, 'bias_instability': 3 * GYRO_N,
                                        'rate_random_walk': GYRO_K},
                               'accel': {'white_noise': ACCEL_N}}, 30_000, RATE, seed=5)
    csv = tmp_path / 'sim.csv'
    t = np.arange(data.shape[0]) / RATE
    np.savetxt(csv, np.column_stack([t, data]), delimiter=',', comments='',
               header='t,gyro_x,gyro_y,gyro_z,accel_x,accel_y,accel_z')
    out = tmp_path / 'report'
    proc = run_command('analyze', csv, '--out', out, '--export', 'kalibr,px4', '--overbound',
                       '--overbound-horizon', '10', '--inflate', '1,2', '--quiet')
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / 'report.json').read_text())
    block = report['overbound']
    assert block['horizon_s'] == 10.0 and block['inflate'] == [1.0, 2.0]
    assert set(block['exports']) == {'kalibr', 'px4'}
    factor = block['exports']['kalibr']['gyroscope_noise_density']['factor']
    assert list(factor.values())[0] > 1.0   # bias instability lifts N
    head = (out / 'export' / 'kalibr_imu.yaml').read_text()
    assert 'horizon 10 s' in head and 'on top of the overbound' in head
    for args, option in ((['--overbound'], '--overbound'),
                         (['--export', 'kalibr', '--overbound-horizon', '5'],
                          '--overbound-horizon'),
                         (['--export', 'kalibr', '--overbound', '--overbound-horizon', '1e6'],
                          '--overbound-horizon'),
                         (['--export', 'kalibr', '--overbound', '--overbound-horizon', 'x'],
                          '--overbound-horizon')):
        proc = run_command('analyze', csv, '--out', tmp_path / 'bad', *args)
        assert proc.returncode == 2 and option in proc.stderr, (args, proc.stderr)
        assert 'Traceback' not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1


def test_overbound_without_a_usable_bound_is_one_input_error(fitted, tmp_path):
    """No finite EDF anywhere (nothing to bound): InputError naming --overbound, no traceback."""
    broken = copy.copy(fitted)
    broken.result = copy.copy(fitted.result)
    broken.result.edf = np.full_like(fitted.result.edf, np.nan)
    with pytest.raises(InputError, match='usable bound') as exc:
        write_exports(tmp_path, broken, ExportOptions(('kalibr',), overbound=True))
    assert exc.value.where == '--overbound'
    with pytest.raises(InputError, match='horizon'):
        write_exports(tmp_path, fitted, ExportOptions(('kalibr',), overbound=True,
                                                      horizon_s=1e-6))
