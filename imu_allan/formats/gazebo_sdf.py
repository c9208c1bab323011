"""
Gazebo and PX4 SITL IMU noise in SDFormat, both ways: write it, and read what it simulates.

Two simulators, read from their own source:

* **Gazebo** (gz-sim, the Jazzy pairing): an SDFormat ``<imu>`` element with one
  ``<noise type="gaussian">`` per axis (``angular_velocity`` / ``linear_acceleration``, ``x y
  z``).  gz-sensors ``GaussianNoiseModel::ApplyImpl`` (src/GaussianNoiseModel.cc:111-154) adds,
  each sample, white noise of std ``stddev`` (PER SAMPLE) plus a bias that is a first-order
  Gauss-Markov process driven by ``dynamic_bias_stddev`` (a continuous DRIVING density, not the
  bias's std) with correlation time ``dynamic_bias_correlation_time``, then rounds to
  ``precision`` (ignored below 1e-6, :103-107).  The bias starts at the turn-on value drawn
  from ``bias_mean`` / ``bias_stddev`` (:85-99).
* **PX4 SITL** (PX4-SITL_gazebo-classic ``gazebo_imu_plugin``): one ``<plugin>`` block with
  ``gyroscopeNoiseDensity`` (continuous N: the plugin multiplies by 1/sqrt(dt),
  src/gazebo_imu_plugin.cpp:198), ``gyroscopeRandomWalk`` (the driving density of the same
  Gauss-Markov bias, :201-205, a random walk only for an infinite correlation time),
  ``gyroscopeBiasCorrelationTime``, ``gyroscopeTurnOnBiasSigma``, accelerometer likewise; one
  value for the three axes of a sensor; missing keys take the defaults of
  include/gazebo_imu_plugin.h:38-54.

Reading (:func:`read_sim_model`) gives the :class:`~imu_allan.core.model.NoiseModel` the file
REALLY simulates: N = stddev / sqrt(f); the Gauss-Markov with sigma = driving density x
sqrt(tau / 2); precision rounding is, for noise spanning several steps, white noise of
precision^2 / 12 per sample, so it adds to N (not to the IEEE quantization term, whose 1/tau^2
Allan variance comes from rounding the integrated angle).  Writing (:func:`export_gazebo`,
:func:`export_px4`) goes the other way from a fitted model; terms these simulators cannot
represent (bias instability, several bias terms, a ramp, a sinusoid) become the one
Gauss-Markov that matches them best over the measured averaging times
(:func:`imu_allan.core.simulation.gauss_markov.best_gauss_markov`), and the file says so.
:meth:`SimImu.corrected` writes the same file back with what the discrepancy workflow added.
"""

import copy
from dataclasses import dataclass, field
import math
from xml.etree import ElementTree

import numpy as np

from ..core.model import NoiseModel
from ..core.simulation import gauss_markov as gm
from ..core.terms import gauss_markov_shape
from ..core.units import AXES, discrete_white_std, is_gyro, si_unit
from ..errors import InputError

GAZEBO_FILE = 'gazebo_imu.sdf'
PX4_FILE = 'px4_sitl_imu.sdf'
CORRECTED_FILE = 'corrected.sdf'

#: SDF path of each axis inside ``<imu>``.
GZ_AXES = {'gyro_x': ('angular_velocity', 'x'), 'gyro_y': ('angular_velocity', 'y'),
           'gyro_z': ('angular_velocity', 'z'), 'accel_x': ('linear_acceleration', 'x'),
           'accel_y': ('linear_acceleration', 'y'), 'accel_z': ('linear_acceleration', 'z')}
#: ``<noise>`` children gz-sensors reads, with SDFormat's defaults.
GZ_FIELDS = {'mean': 0.0, 'stddev': 0.0, 'bias_mean': 0.0, 'bias_stddev': 0.0,
             'dynamic_bias_stddev': 0.0, 'dynamic_bias_correlation_time': 0.0,
             'precision': 0.0}
#: Noise types gz-sensors builds a GaussianNoiseModel for (src/Noise.cc:54-57), and 'none'.
GZ_TYPES = ('gaussian', 'gaussian_quantized', 'none')
#: gz-sensors treats a precision within 1e-6 of zero as no rounding (GaussianNoiseModel.cc:106).
GZ_MIN_PRECISION = 1e-6
#: PX4 plugin keys per sensor: (noise density, random walk, correlation time, turn-on sigma).
PX4_KEYS = {'gyro': ('gyroscopeNoiseDensity', 'gyroscopeRandomWalk',
                     'gyroscopeBiasCorrelationTime', 'gyroscopeTurnOnBiasSigma'),
            'accel': ('accelerometerNoiseDensity', 'accelerometerRandomWalk',
                      'accelerometerBiasCorrelationTime', 'accelerometerTurnOnBiasSigma')}
#: The plugin's defaults (include/gazebo_imu_plugin.h:38-54, PX4-SITL_gazebo-classic 807b67b).
PX4_DEFAULTS = {'gyroscopeNoiseDensity': 0.0008726646, 'gyroscopeRandomWalk': 0.0,
                'gyroscopeBiasCorrelationTime': 1000.0, 'gyroscopeTurnOnBiasSigma': 0.0,
                'accelerometerNoiseDensity': 0.00637, 'accelerometerRandomWalk': 0.0,
                'accelerometerBiasCorrelationTime': 300.0,
                'accelerometerTurnOnBiasSigma': 0.0}
#: Averaging-time band (s) for the Gauss-Markov approximation when the model carries none.
DEFAULT_TAU_MAX_S = 3600.0

#: Each key as documented (the noise the user means: :meth:`SimImu.intended_model`) and as the
#: simulator's code produces it (:meth:`SimImu.noise_model`).  The discrepancy findings
#: compare recordings with the first; the single-recording workflow starts from the second.
CONVENTIONS = {
    'gazebo': {
        'stddev': ('the white noise in rad/s (m/s^2) with no rate in it: a density N, the '
                   'same sensor at any rate (gazebo-classic#2670; PX4-gazebo-models copied '
                   'NoiseDensity into it)',
                   'a per-sample std, not scaled by dt: N = stddev / sqrt(f)'),
        'dynamic_bias_stddev': ('the std of the slowly varying bias (gz-sensors#616)',
                                'the driving density of its Gauss-Markov: std = value '
                                'sqrt(tau / 2)'),
        'dynamic_bias_correlation_time': ('tau_c of that bias, s', 'the same'),
        'bias_mean': ('the mean of the turn-on bias', 'its sign drawn at random at each start '
                      '(gz-sensors#360); with a dynamic bias it starts that process and '
                      'decays with tau_c'),
        'bias_stddev': ('the std of the turn-on bias', 'the same, with the random sign'),
        'mean': ('a constant offset (added to the turn-on mean)', 'the same'),
        'precision': ('rounding of each sample: white noise of precision^2 / 12 per sample',
                      'the same (ignored below 1e-6)'),
    },
    'px4': {
        'NoiseDensity': ('the white noise density N', 'the same (x 1 / sqrt(dt) per sample)'),
        'RandomWalk': ('the driving density of the Gauss-Markov bias (std = value '
                       'sqrt(tau / 2))', 'the same'),
        'BiasCorrelationTime': ('tau_c of that bias, s', 'the same'),
        'TurnOnBiasSigma': ('the std of the turn-on bias (mean 0)', 'the same'),
    },
}
#: Finding classes whose factor says how to change a simulator value: (term, Gazebo key,
#: PX4 key index in PX4_KEYS); the value is divided by the factor at the simulator's rate.
SCALE_KEYS = {('white_scale', 'white_noise'): ('stddev', 0),
              ('bias_scale', 'gauss_markov'): ('dynamic_bias_stddev', 1)}


def _of_sensor(axes, sensor):
    """Return the axes of ``axes`` that belong to ``sensor`` ('gyro' or 'accel')."""
    return [a for a in axes if is_gyro(a) == (sensor == 'gyro')]


def _version():
    from .. import __version__
    return __version__


def _num(x):
    """Return a float as SDF text (enough digits to round-trip the simulation)."""
    return f'{x:.9g}'


def _comment_text(lines, indent=''):
    """XML comment body: one line per entry, no '--' (not allowed inside a comment)."""
    body = '\n'.join(f'{indent}  ' + line.replace('--', '- -') for line in lines)
    return f'\n{body}\n{indent}'


def _inflation(inflate):
    """``inflate`` as (white, walk) factors: a number applies to both."""
    if inflate is None:
        return 1.0, 1.0
    if isinstance(inflate, (int, float)):
        return float(inflate), float(inflate)
    white, walk = (float(v) for v in inflate)
    return white, walk


# ---------------------------------------------------------------------------------------------
# Reading


def looks_like_sdf(path):
    """Return True when a model file is XML (SDF, world, URDF or a fragment) rather than YAML."""
    if str(path).lower().endswith(('.sdf', '.world', '.xml', '.urdf')):
        return True
    try:
        with open(path, 'rb') as stream:
            head = stream.read(512)
    except OSError:
        return False
    return head.lstrip(b'\xef\xbb\xbf \t\r\n').startswith(b'<')


def _parse_xml(text, where):
    """Parse XML keeping comments; a fragment of several elements is wrapped in one root."""
    def parse(body):
        parser = ElementTree.XMLParser(target=ElementTree.TreeBuilder(insert_comments=True))
        parser.feed(body)
        return parser.close()
    try:
        return parse(text), False
    except ElementTree.ParseError as first:
        body = text
        if body.lstrip().startswith('<?xml'):
            body = body[body.index('?>') + 2:]
        try:
            return parse(f'<imu_allan_fragment>{body}</imu_allan_fragment>'), True
        except ElementTree.ParseError:
            line, col = first.position
            raise InputError(where, f'not XML (line {line}, column {col}: '
                                    f'{str(first).split(":")[0]})') from None


def _blocks(root):
    """IMU noise blocks in a tree: ('gazebo', imu element, parent) / ('px4', plugin, parent)."""
    parents = {child: parent for parent in root.iter() for child in parent}
    found = []
    for elem in root.iter():
        if not isinstance(elem.tag, str):
            continue
        if elem.tag == 'imu' and any(elem.find(s) is not None for s, _ in GZ_AXES.values()):
            found.append(('gazebo', elem, parents.get(elem)))
        elif elem.tag == 'plugin' and (
                'gazebo_imu_plugin' in elem.get('filename', '')
                or any(elem.find(k) is not None for keys in PX4_KEYS.values() for k in keys)):
            found.append(('px4', elem, parents.get(elem)))
    return found


def _describe(kind, elem, parent):
    if kind == 'px4':
        return f'gazebo_imu_plugin {elem.get("name", "")!r}'
    name = parent.get('name', '') if parent is not None else ''
    return f'<imu> of sensor {name!r}' if name else '<imu>'


def _float(elem, tag, where, label, default):
    child = elem.find(tag)
    if child is None or child.text is None or not child.text.strip():
        return default
    try:
        value = float(child.text.strip())
    except ValueError:
        raise InputError(where, f'{label}/{tag} is not a number: {child.text.strip()!r}') \
            from None
    if not math.isfinite(value):
        raise InputError(where, f'{label}/{tag} is not finite')
    return value


@dataclass
class SimImu:
    """
    The IMU noise block of a Gazebo or PX4 SDF file, in the simulator's own terms.

    ``kind`` is ``'gazebo'`` or ``'px4'``; ``params`` holds, for gazebo, ``{axis: {noise
    field: value, 'type': str}}`` and for PX4 ``{plugin key: value}`` (defaults filled in,
    listed in ``defaulted``, and for gazebo the ``<noise>`` fields the file does not write, as
    ``group/letter/noise/field``); ``rate_hz`` is the sensor's ``<update_rate>`` (gazebo) or
    None.
    """

    kind: str
    source: str
    text: str
    params: dict
    rate_hz: float = None
    label: str = ''
    defaulted: list = field(default_factory=list)

    def rate_for(self, data_rate_hz=None):
        """Return the rate of the per-sample values: the SDF's update rate, else the data's."""
        rate = self.rate_hz or data_rate_hz
        if self.kind == 'gazebo' and not rate:
            raise InputError(self.source, 'the sensor has no <update_rate>: give the data rate '
                                          'to convert its per-sample stddev')
        return rate

    def noise_model(self, data_rate_hz=None):
        """
        Return the :class:`NoiseModel` the simulator really produces, and notes on the conversion.

        The conversions of the module docstring (gz: N = sqrt(stddev^2 + precision^2 / 12) /
        sqrt(f), the rounding term only where gz-sensors rounds); constant offsets (mean,
        turn-on bias) do not change the Allan deviation and are left out.
        """
        rate = self.rate_for(data_rate_hz)
        notes = [f'{self.source}: {self.label} read as the noise it simulates']
        if data_rate_hz and abs(rate / data_rate_hz - 1.0) > 0.02:
            notes.append(f'the simulated IMU runs at {rate:g} Hz, the data at '
                         f'{data_rate_hz:g} Hz: compared as continuous-time densities')
        terms = {}
        if self.kind == 'gazebo':
            notes[0] += (f' at {rate:g} Hz: N = stddev / sqrt(f) (stddev is per sample), '
                         f'Gauss-Markov sigma = dynamic_bias_stddev sqrt(tau / 2) (a driving '
                         f'density)')
            rounded, offsets, idle = [], [], []
            for axis, p in self.params.items():
                if p['type'] == 'none':
                    continue
                white = p['stddev'] ** 2
                if p['precision'] > GZ_MIN_PRECISION:
                    white += p['precision'] ** 2 / 12.0
                    rounded.append(axis)
                axis_terms = {}
                if white > 0:
                    axis_terms['white_noise'] = math.sqrt(white / rate)
                drive, tau = p['dynamic_bias_stddev'], p['dynamic_bias_correlation_time']
                if drive > 0 and tau > 0:
                    axis_terms['gauss_markov'] = {'sigma': gm.stationary_sigma(drive, tau),
                                                  'tau_c': tau}
                elif drive > 0:
                    idle.append(axis)
                if p['mean'] or p['bias_mean'] or p['bias_stddev']:
                    offsets.append(axis)
                if axis_terms:
                    terms[axis] = axis_terms
            if rounded:
                notes.append(f'{", ".join(rounded)}: precision rounding counted as white noise '
                             f'of precision^2/12 per sample (valid when the noise spans '
                             f'several steps)')
            if idle:
                notes.append(f'{", ".join(idle)}: dynamic_bias_stddev without a positive '
                             f'dynamic_bias_correlation_time: gz-sensors ignores it')
            if offsets:
                notes.append(f'{", ".join(offsets)}: mean / turn-on bias are offsets, not '
                             f'noise: left out')
        else:
            notes[0] += (': N = the noise density (continuous), Gauss-Markov sigma = '
                         'RandomWalk sqrt(tau / 2) (a driving density)')
            for sensor, (n_key, rw_key, tau_key, _) in PX4_KEYS.items():
                sensor_terms = {}
                if self.params[n_key] > 0:
                    sensor_terms['white_noise'] = self.params[n_key]
                if self.params[rw_key] > 0:
                    tau = self.params[tau_key]
                    sensor_terms['gauss_markov'] = {
                        'sigma': gm.stationary_sigma(self.params[rw_key], tau), 'tau_c': tau}
                for axis in _of_sensor(AXES, sensor) if sensor_terms else ():
                    terms[axis] = copy.deepcopy(sensor_terms)
            if self.defaulted:
                notes.append(f'plugin defaults used for {", ".join(self.defaulted)}')
        if not terms:
            raise InputError(self.source, f'{self.label} simulates no noise')
        return NoiseModel(terms, rate), notes

    def intended_model(self, data_rate_hz):
        """
        Return the :class:`NoiseModel` the file's keys are documented to mean, and a note.

        :data:`CONVENTIONS`, first column: Gazebo white N = stddev (a density; precision
        rounding adds precision^2 / 12 per sample at ``data_rate_hz``), Gauss-Markov sigma =
        dynamic_bias_stddev, turn-on bias N(bias_mean + mean, bias_stddev); PX4 as coded
        (its keys are densities), turn-on bias N(0, TurnOnBiasSigma).  A bias key the file
        sets to 0 (dynamic_bias_stddev, RandomWalk; not one it leaves out) is a Gauss-Markov of
        sigma 0, a *zeroed* term the findings name when the data show it.  The recordings are
        compared with this (:func:`imu_allan.core.discrepancy.find_discrepancies`).
        """
        terms, turn_on = {}, {}
        if self.kind == 'gazebo':
            note = (f'{self.source}: {self.label} read as documented: stddev is the white '
                    f'noise density, dynamic_bias_stddev the bias std, bias_mean / '
                    f'bias_stddev the turn-on bias')
            for axis, p in self.params.items():
                if p['type'] == 'none':
                    continue
                white = p['stddev'] ** 2
                if p['precision'] > GZ_MIN_PRECISION:
                    white += p['precision'] ** 2 / 12.0 / data_rate_hz
                axis_terms = {}
                if white > 0:
                    axis_terms['white_noise'] = math.sqrt(white)
                std, tau = p['dynamic_bias_stddev'], p['dynamic_bias_correlation_time']
                if std > 0 and tau > 0:
                    axis_terms['gauss_markov'] = {'sigma': std, 'tau_c': tau}
                elif axis_terms and self.written(axis, 'dynamic_bias_stddev'):
                    # the dynamic bias set to zero: a zeroed term (tau_c 0: unknown)
                    axis_terms['gauss_markov'] = {'sigma': 0.0, 'tau_c': tau}
                if axis_terms:
                    terms[axis] = axis_terms
                turn_on[axis] = {'mean': p['bias_mean'] + p['mean'], 'sigma': p['bias_stddev']}
        else:
            note = (f'{self.source}: {self.label} read as documented: NoiseDensity the white '
                    f'noise density, RandomWalk the driving density of the Gauss-Markov bias')
            model, _ = self.noise_model(data_rate_hz)
            terms = model.terms
            for sensor, keys in PX4_KEYS.items():
                for axis in _of_sensor(AXES, sensor):
                    turn_on[axis] = {'mean': 0.0, 'sigma': self.params[keys[3]]}
                    if axis in terms and self.params[keys[1]] == 0 and \
                            keys[1] not in self.defaulted:  # RandomWalk set to 0: zeroed
                        terms[axis]['gauss_markov'] = {'sigma': 0.0,
                                                       'tau_c': self.params[keys[2]]}
        if not terms:
            raise InputError(self.source, f'{self.label} simulates no noise')
        return NoiseModel(terms, None, turn_on), note

    def written(self, axis, name):
        """Return True when the file writes gz ``<noise>`` field ``name`` of ``axis``."""
        group, letter = GZ_AXES[axis]
        return f'{group}/{letter}/noise/{name}' not in self.defaulted

    def key_of(self, axis, term):
        """Return the key that sets ``term`` on ``axis`` (Gazebo: its path), and its value."""
        for (_, t), (gz_key, px4_index) in SCALE_KEYS.items():
            if t != term:
                continue
            if self.kind == 'gazebo':
                if axis not in self.params:
                    return None, None
                group, letter = GZ_AXES[axis]
                return f'{group}/{letter}/noise/{gz_key}', self.params[axis][gz_key]
            key = PX4_KEYS['gyro' if is_gyro(axis) else 'accel'][px4_index]
            return key, self.params[key]
        return None, None

    def suggest(self, findings, data_rates_hz):
        """
        Set ``parameter`` and ``suggested`` on the findings a simulator value can correct.

        A white or bias scale found as ``factor`` (at 1 Hz, with ``rate_exponent``, when it
        scales with the rate) means the value gives factor(f) x the intended noise at rate f:
        the suggested value is the file's divided by factor(f), at the sensor's
        ``<update_rate>`` (Gazebo) or else the median rate of the recordings, noted in the
        finding's evidence as ``suggested_at_hz``.
        """
        rate = self.rate_hz or float(np.median(data_rates_hz))
        for f in findings:
            if (f.cls, f.term) not in SCALE_KEYS or f.factor is None or f.factor <= 0:
                continue
            key, value = self.key_of(f.axis, f.term)
            if key is None:
                continue
            at_rate = f.factor * (rate ** f.rate_exponent if f.rate_exponent is not None
                                  else 1.0)
            f.parameter, f.suggested = key, value / at_rate
            f.evidence['suggested_at_hz'] = rate
            f.evidence['configured'] = value
        for f in findings:
            if f.cls == 'biased_drive' and f.term == 'gauss_markov':
                f.parameter = self.key_of(f.axis, 'gauss_markov')[0]  # no value corrects it
            elif f.cls == 'zeroed_term' and f.term == 'gauss_markov' and f.evidence['needed']:
                self._suggest_zeroed(f, rate)
        return findings

    def _suggest_zeroed(self, f, rate):
        """
        Set a zeroed Gauss-Markov's key to what the data show, in the simulator's own terms.

        The data stand for the noise the simulator should make: the key is set as
        :meth:`corrected` would write it (gz: ``dynamic_bias_stddev`` the driving density and
        ``stddev`` N sqrt(f); PX4: RandomWalk the driving density, NoiseDensity N), with the
        correlation time and the white-noise key beside it in ``evidence.also``.
        """
        sigma, tau_c = f.evidence['needed']['sigma'], f.evidence['needed']['tau_c']
        density = f.evidence.get('density') or {}
        also = {}
        if self.kind == 'gazebo':
            group, letter = GZ_AXES[f.axis]
            terms = {'gauss_markov': {'sigma': sigma, 'tau_c': tau_c}}
            if density:
                terms['white_noise'] = {'value': density['measured']}
            values, _ = gazebo_values(terms, rate, (tau_c, tau_c))
            f.parameter = f'{group}/{letter}/noise/dynamic_bias_stddev'
            f.suggested = values['dynamic_bias_stddev']
            also[f'{group}/{letter}/noise/dynamic_bias_correlation_time'] = tau_c
            if density:
                also[f'{group}/{letter}/noise/stddev'] = values['stddev']
        else:
            n_key, rw_key, tau_key, _ = PX4_KEYS['gyro' if is_gyro(f.axis) else 'accel']
            f.parameter, f.suggested = rw_key, gm.driving_density(sigma, tau_c)
            also[tau_key] = tau_c
            if density:
                also[n_key] = density['measured']
        f.evidence.update(suggested_at_hz=rate, also=also)

    def corrected(self, result, data_source=None):
        """
        Return the same file with the discrepancy workflow's additions in the simulator's terms.

        ``result`` is a :class:`~imu_allan.core.discrepancy.DiscrepancyResult` run with this
        file's :meth:`noise_model`.  Only the axes (Gazebo) or sensors (PX4) the workflow
        changed are rewritten, each after a comment saying what was added and how it is
        represented.  Returns the text.
        """
        root, fragment = _parse_xml(self.text, self.source)
        kind, elem, _ = _single_block(root, self.source)
        measured = result.measured
        rate = self.rate_for(measured.rate_hz)
        tau_range = (float(measured.tau[0]), float(measured.tau[-1]))
        final = result.final_model.terms
        steps = {}
        for step in result.steps:
            steps.setdefault(step.axis, []).append(step)
        head = [f'Corrected by imu_allan {_version()} discrepancy against '
                f'{data_source or "the measured data"} '
                f'({measured.rate_hz:.6g} Hz, averaging times {tau_range[0]:.3g}-'
                f'{tau_range[1]:.3g} s); the changed blocks carry a comment.']
        if kind == 'gazebo':
            for axis in (a for a in AXES if a in steps):
                group, letter = GZ_AXES[axis]
                holder = elem.find(group).find(letter)
                noise = holder.find('noise')
                old = self.params[axis]
                values, lines = gazebo_values(final[axis], rate, tau_range,
                                              precision=old['precision'] or None)
                _set_children(noise, values)
                lines = [f'{axis}: ' + _steps_text(steps[axis], axis, final[axis])] + lines
                _comment_before(holder, noise, lines)
        else:
            for sensor, keys in PX4_KEYS.items():
                axes = _of_sensor(steps, sensor)
                if not axes:
                    continue
                values, lines = px4_values({a: final[a] for a in _of_sensor(result.axes, sensor)},
                                           sensor, tau_range, rate)
                values[keys[3]] = self.params[keys[3]]  # the turn-on bias stays
                _set_children(elem, values)
                lines = [f'{a}: ' + _steps_text(steps[a], a, final[a]) for a in axes] + lines
                _comment_before(elem, elem.find(keys[0]), lines)
        return f'<!--{_comment_text(head)}-->\n' + _serialize(root, fragment)


def _single_block(root, where):
    found = _blocks(root)
    if not found:
        raise InputError(where, 'no <imu> element with noise and no gazebo_imu_plugin block')
    if len(found) > 1:
        names = ', '.join(_describe(*b) for b in found)
        raise InputError(where, f'{len(found)} IMU noise blocks ({names}): keep one')
    return found[0]


def read_sim_model(path):
    """
    Read a Gazebo ``<imu>`` (or an .sdf / world file holding one) or a PX4 plugin block.

    Returns a :class:`SimImu`.  Raises :class:`InputError` naming the file for anything that is
    not one readable noise block: not XML, no or several IMU blocks, a noise type gz-sensors
    does not simulate as Gaussian, a negative or non-numeric value.
    """
    where = str(path)
    try:
        with open(path, encoding='utf-8') as stream:
            text = stream.read()
    except OSError as exc:
        raise InputError(where, f'cannot read ({exc.strerror or exc})') from None
    except UnicodeDecodeError:
        raise InputError(where, 'not a text file') from None
    root, _ = _parse_xml(text, where)
    kind, elem, parent = _single_block(root, where)
    label = _describe(kind, elem, parent)
    if kind == 'px4':
        params, defaulted = {}, []
        for keys in PX4_KEYS.values():
            for key in keys:
                value = _float(elem, key, where, 'plugin', None)
                if value is None:
                    value = PX4_DEFAULTS[key]
                    defaulted.append(key)
                if value < 0:
                    raise InputError(where, f'plugin/{key} is negative ({value:g})')
                params[key] = value
            if params[keys[2]] <= 0:  # the plugin asserts it (gazebo_imu_plugin.cpp:79, :92)
                raise InputError(where, f'plugin/{keys[2]} must be > 0')
        return SimImu('px4', where, text, params, None, label, defaulted)
    params, defaulted = {}, []
    for axis, (group, letter) in GZ_AXES.items():
        holder = elem.find(group)
        holder = holder.find(letter) if holder is not None else None
        noise = holder.find('noise') if holder is not None else None
        if noise is None:
            continue
        path_label = f'{group}/{letter}/noise'
        kind_text = (noise.get('type') or (noise.findtext('type') or '')).strip()
        if kind_text not in GZ_TYPES:
            raise InputError(where, f'{path_label}: noise type {kind_text or "(missing)"!r} is '
                                    f'not one gz-sensors simulates as Gaussian '
                                    f'({", ".join(GZ_TYPES)})')
        p = {'type': kind_text}
        for name, default in GZ_FIELDS.items():
            p[name] = _float(noise, name, where, path_label, default)
            if noise.find(name) is None:
                defaulted.append(f'{path_label}/{name}')
            if p[name] < 0 and name not in ('mean', 'bias_mean'):
                raise InputError(where, f'{path_label}/{name} is negative ({p[name]:g})')
        params[axis] = p
    if not params:
        raise InputError(where, f'{label} has no <noise> element')
    rate = None
    if parent is not None and parent.tag == 'sensor':
        rate = _float(parent, 'update_rate', where, 'sensor', None)
        if rate is not None and rate < 0:
            raise InputError(where, f'sensor/update_rate is negative ({rate:g})')
    return SimImu('gazebo', where, text, params, rate or None, label, defaulted)


# ---------------------------------------------------------------------------------------------
# From a noise model to the simulators' values


def gazebo_values(axis_terms, rate_hz, tau_range, precision=None, inflate=(1.0, 1.0)):
    """
    gz-sensors ``<noise>`` values of one axis, and comment lines on how they were made.

    stddev = N sqrt(f) (per sample); ``precision`` given (the file's own) is kept and its
    rounding noise (precision^2 / 12 per sample) taken out of stddev, else it comes from
    quantization Q as the rate resolution sqrt(12) Q f; the bias terms become
    dynamic_bias_stddev (driving density) and dynamic_bias_correlation_time of their one
    Gauss-Markov over ``tau_range``.  ``inflate`` = (white, walk) multiplies stddev and the
    driving density.
    """
    lines = []
    white = discrete_white_std(axis_terms.get('white_noise', {}).get('value', 0.0), rate_hz) ** 2
    q = axis_terms.get('quantization', {}).get('value')
    if precision is not None:
        if precision > GZ_MIN_PRECISION:
            white -= precision ** 2 / 12.0
        if q:
            lines.append('quantization cannot be added to the existing precision: left out')
    elif q:
        precision = math.sqrt(12.0) * q * rate_hz
        lines.append(f'precision = sqrt(12) Q f from quantization Q = {q:.3g}; gz-sensors rounds '
                     f'each sample: white noise of precision^2/12 per sample, not the '
                     f'1/tau^2 angle-quantization slope'
                     + (' (below 1e-6: gz-sensors ignores it)'
                        if precision <= GZ_MIN_PRECISION else ''))
    if 'white_noise' not in axis_terms:
        lines.append('white noise not detected (no upper limit either): stddev 0')
    elif white < 0:
        lines.append('the white noise is below the rounding noise of precision: stddev 0')
    values = {'stddev': math.sqrt(max(white, 0.0)) * inflate[0]}
    fit = gm.best_gauss_markov(axis_terms, tau_range, rate_hz)
    if fit is None:
        values['dynamic_bias_stddev'] = 0.0
        values['dynamic_bias_correlation_time'] = 0.0
    else:
        values['dynamic_bias_stddev'] = fit.drive * inflate[1]
        values['dynamic_bias_correlation_time'] = fit.tau_c
        if not fit.exact:
            lines.append(('bias: ' if fit.replaces == ('rate_random_walk',) else
                          'gz-sensors has one Gauss-Markov bias per axis: ') + fit.how)
    if precision:
        values['precision'] = precision
    return values, lines


def _gm_weight(fit, tau_range):
    """Mean Gauss-Markov AVAR over the band (which axis's bias is the worst)."""
    tau = np.geomspace(tau_range[0], tau_range[1], 24)
    return float(np.mean(fit.sigma ** 2 * gauss_markov_shape(tau, fit.tau_c)))


def px4_values(terms_by_axis, sensor, tau_range, rate_hz, inflate=(1.0, 1.0)):
    """
    PX4 plugin values of one sensor (one value for its axes: the worst axis), and notes.

    NoiseDensity = the largest N; RandomWalk / BiasCorrelationTime = the driving density and
    tau of the Gauss-Markov (:func:`best_gauss_markov`) with the largest Allan variance over
    ``tau_range``; quantization has no plugin key and is left out.
    """
    n_key, rw_key, tau_key, on_key = PX4_KEYS[sensor]
    lines = []
    whites = {a: t['white_noise']['value'] for a, t in terms_by_axis.items()
              if 'white_noise' in t}
    values = {}
    if whites:
        worst = max(whites, key=whites.get)
        values[n_key] = whites[worst] * inflate[0]
        lines.append(f'{n_key}: worst axis {worst}')
    fits = {a: gm.best_gauss_markov(t, tau_range, rate_hz) for a, t in terms_by_axis.items()}
    fits = {a: f for a, f in fits.items() if f is not None}
    if fits:
        worst = max(fits, key=lambda a: _gm_weight(fits[a], tau_range))
        values[rw_key] = fits[worst].drive * inflate[1]
        values[tau_key] = fits[worst].tau_c
        lines.append(f'{rw_key}, {tau_key}: worst axis {worst}, '
                     + ('its Gauss-Markov' if fits[worst].exact else fits[worst].how))
    else:
        values[rw_key] = 0.0
        values[tau_key] = PX4_DEFAULTS[tau_key]
    values[on_key] = 0.0
    if any('quantization' in t for t in terms_by_axis.values()):
        lines.append('quantization: no plugin key, left out')
    return values, lines


def _steps_text(steps, axis, axis_terms):
    parts = []
    for step in steps:
        params = axis_terms.get(step.effect, {})
        shown = ', '.join(f'{k} {v:.4g}' + ('' if k in ('tau_c', 'frequency_hz') else
                                            f' {si_unit(axis, step.effect)}')
                          for k, v in params.items()) if params else 'refitted'
        where = (f' at {step.tau_range[0]:.3g}-{step.tau_range[1]:.3g} s'
                 if step.tau_range else '')
        parts.append(f'added {step.effect} ({shown}){where}, gap {step.gap_before:.2f} -> '
                     f'{step.gap_after:.2f}')
    return '; '.join(parts)


def _set_children(elem, values):
    """Set (or append, indented like the last child) ``<tag>value</tag>`` children."""
    children = [c for c in elem if isinstance(c.tag, str)]
    for tag, value in values.items():
        child = elem.find(tag)
        if child is None:
            child = ElementTree.SubElement(elem, tag)
            if children:
                last = children[-1]
                child.tail, last.tail = last.tail, children[-2].tail if len(children) > 1 \
                    else elem.text
            children.append(child)
        child.text = _num(value)


def _comment_before(parent, child, lines):
    index = list(parent).index(child)
    # the comment takes the child's indentation and hands the same on to the child
    space = (parent.text if index == 0 else parent[index - 1].tail) or '\n'
    comment = ElementTree.Comment(_comment_text(lines, space.rsplit('\n', 1)[-1]))
    comment.tail = space
    parent.insert(index, comment)


def _serialize(root, fragment):
    if fragment:
        return (root.text or '') + ''.join(ElementTree.tostring(c, encoding='unicode')
                                           for c in root)
    return ElementTree.tostring(root, encoding='unicode') + '\n'


# ---------------------------------------------------------------------------------------------
# Writers (exporters ``gazebo`` and ``px4``)


@dataclass
class ModelInput:
    """
    What the writers read: a noise model, where it was measured, and its upper limits.

    ``upper_limits``: ``{axis: {term: value}}`` (SI, 95 %) of terms not resolved; else
    ``upper_limit(axis, term)`` gives them (a FittedModel's); ``result``: the Allan curve
    whose averaging times the header names (None: 1/rate to the default horizon).
    """

    model: NoiseModel
    rate_hz: float = None
    result: object = None  # AllanResult or None
    upper_limits: dict = field(default_factory=dict)
    upper_limit: object = None  # callable (axis, term) -> float, or None
    source: str = None

    @classmethod
    def of(cls, fitted):
        """Return the input of an Analysis, a FittedModel, a NoiseModel or a ModelInput."""
        from ..core.analysis import Analysis
        from ..core.fit.fitted_model import FittedModel
        if isinstance(fitted, cls):
            return fitted
        if isinstance(fitted, Analysis):
            return cls(fitted.fit.model, fitted.rate_hz, fitted.result, fitted.upper_limits,
                       fitted.fit.upper_limit, fitted.source)
        if isinstance(fitted, FittedModel):
            return cls(fitted.model, fitted.rate_hz, fitted.result,
                       upper_limit=fitted.upper_limit)
        if isinstance(fitted, NoiseModel):
            return cls(fitted, fitted.rate_hz)
        raise TypeError('expected an Analysis, a FittedModel or a NoiseModel')


def _model_input(fitted, rate_hz, source=None):
    """Return (terms per axis, rate, tau range, upper limits used, source) of a ModelInput."""
    given = ModelInput.of(fitted)
    model, result, upper, limit_of = (given.model, given.result, given.upper_limits or {},
                                      given.upper_limit)
    source = source or given.source
    rate = rate_hz or given.rate_hz or model.rate_hz
    if not rate:
        raise ValueError('the sample rate is needed (rate_hz)')
    if result is not None and len(result.tau):
        tau_range = (float(result.tau[0]), float(result.tau[-1]))
    else:
        tau_range = (1.0 / rate, DEFAULT_TAU_MAX_S)
    terms, marked = {}, {}
    for axis in model.axes:
        axis_terms = copy.deepcopy(model.terms[axis])
        limits = dict(upper.get(axis, {}))
        if limit_of is not None and not limits:
            for term in ('white_noise', 'rate_random_walk'):
                value = limit_of(axis, term) if term not in axis_terms else math.nan
                if math.isfinite(value):
                    limits[term] = value
        if 'white_noise' not in axis_terms and 'white_noise' in limits:
            axis_terms['white_noise'] = {'value': limits['white_noise']}
            marked.setdefault(axis, []).append('white_noise')
        if not any(t in axis_terms for t in gm.BIAS_TERMS) and 'rate_random_walk' in limits:
            axis_terms['rate_random_walk'] = {'value': limits['rate_random_walk']}
            marked.setdefault(axis, []).append('rate_random_walk')
        terms[axis] = axis_terms
    return terms, rate, tau_range, marked, source


def _header(kind, source, rate, tau_range, inflate, extra):
    infl = ('none' if inflate == (1.0, 1.0) else
            f'white noise x {inflate[0]:g}, bias (driving density) x {inflate[1]:g}')
    return [f'{kind} IMU noise from imu_allan {_version()}: Allan deviation of '
            f'{source or "(unnamed input)"}, sampled at {rate:.6g} Hz, averaging times '
            f'{tau_range[0]:.3g}-{tau_range[1]:.3g} s.'] + extra + [
        f'Inflation: {infl}. SI units.']


def export_gazebo(fitted, rate_hz=None, inflate=1.0, source=None):
    """
    Gazebo (gz-sensors) SDF ``<sensor type="imu">`` with one ``<noise>`` per axis.

    ``fitted``: an Analysis (it also gives the source, the band and the 95 % upper limits used
    for undetected white noise or random walk), a FittedModel or a NoiseModel; ``rate_hz``:
    the rate the per-sample stddev refers to (default: the fit's); ``inflate``: white-noise
    and bias factors, one number for both (default 1: none); ``source``: the input named in
    the header (default: the Analysis's).  Returns ``(values, text)``: ``{'rate_hz', 'axes':
    {axis: {stddev, dynamic_bias_stddev, dynamic_bias_correlation_time[, precision]}},
    'upper_limits': {axis: [terms]}}`` (SI; stddev per sample, dynamic_bias_stddev a
    continuous driving density) and the file content (:data:`GAZEBO_FILE`).
    """
    inflate = _inflation(inflate)
    terms, rate, tau_range, marked, source = _model_input(fitted, rate_hz, source)
    head = _header('Gazebo (gz-sensors)', source, rate, tau_range, inflate, [
        f'stddev is PER SAMPLE at {rate:.6g} Hz: stddev = N sqrt(f) (N the continuous white '
        f'noise density); keep <update_rate> at {rate:.6g} or scale stddev by sqrt(f_new / f).',
        'dynamic_bias_stddev is the continuous DRIVING density sigma_b of the Gauss-Markov '
        'bias (gz-sensors GaussianNoiseModel.cc: sigma_b_d = sqrt(-sigma_b^2 tau / 2 '
        'expm1(-2 dt / tau))), not its std (= sigma_b sqrt(tau / 2)); tau = '
        'dynamic_bias_correlation_time, s.',
        'Axis rule: per axis (each axis has its own noise block).'])
    out = {'rate_hz': rate, 'axes': {}, 'upper_limits': marked}
    blocks = []
    for group in ('angular_velocity', 'linear_acceleration'):
        inner = []
        for letter in 'xyz':
            axis = next(a for a, g in GZ_AXES.items() if g == (group, letter))
            if axis not in terms:
                continue
            values, lines = gazebo_values(terms[axis], rate, tau_range, inflate=inflate)
            out['axes'][axis] = values
            if axis in marked:
                lines.insert(0, f'{", ".join(marked[axis])} not detected: its 95 % upper limit')
            body = ''.join(f'          <{k}>{_num(v)}</{k}>\n' for k, v in values.items())
            lines = [f'{axis}: {line}' for line in lines]
            note = (f'        <!--{_comment_text(lines, "        ")}-->\n' if lines else '')
            inner.append(f'      <{letter}>\n{note}        <noise type="gaussian">\n'
                         f'          <mean>0</mean>\n{body}'
                         f'        </noise>\n      </{letter}>\n')
        if inner:
            blocks.append(f'    <{group}>\n{"".join(inner)}    </{group}>\n')
    text = (f'<!--{_comment_text(head)}-->\n<sensor name="imu_sensor" type="imu">\n'
            f'  <always_on>1</always_on>\n  <update_rate>{_num(rate)}</update_rate>\n'
            f'  <imu>\n{"".join(blocks)}  </imu>\n</sensor>\n')
    return out, text


def export_px4(fitted, rate_hz=None, inflate=1.0, source=None):
    """
    PX4 SITL ``gazebo_imu_plugin`` block: continuous densities, worst axis per sensor.

    Same arguments as :func:`export_gazebo`; ``values`` is ``{plugin key: value}`` plus
    ``rate_hz`` and ``upper_limits``.
    """
    inflate = _inflation(inflate)
    terms, rate, tau_range, marked, source = _model_input(fitted, rate_hz, source)
    head = _header('PX4 SITL gazebo_imu_plugin', source, rate, tau_range, inflate, [
        '*NoiseDensity = N, continuous (the plugin multiplies by 1/sqrt(dt), '
        'gazebo_imu_plugin.cpp:198); it runs at the physics step, no rate needed.',
        '*RandomWalk is the continuous DRIVING density of the Gauss-Markov bias with '
        '*BiasCorrelationTime tau (gazebo_imu_plugin.cpp:201-205), not a pure random walk; '
        '*TurnOnBiasSigma = 0 (a turn-on bias is not visible in the Allan deviation).',
        'Axis rule: one value per sensor, the worst axis (named below).'])
    out = {'rate_hz': rate, 'upper_limits': marked}
    lines_all, body = [], []
    for sensor in PX4_KEYS:
        sensor_terms = {a: terms[a] for a in _of_sensor(terms, sensor)}
        if not sensor_terms:
            continue
        values, lines = px4_values(sensor_terms, sensor, tau_range, rate, inflate)
        out.update(values)
        lines_all += lines
        body += [f'  <{k}>{_num(v)}</{k}>\n' for k, v in values.items()]
    for axis, names in marked.items():
        lines_all.append(f'{axis}: {", ".join(names)} not detected: its 95 % upper limit')
    text = (f'<!--{_comment_text(head + lines_all)}-->\n'
            f'<plugin name="rotors_gazebo_imu_plugin" filename="libgazebo_imu_plugin.so">\n'
            f'  <robotNamespace/>\n  <linkName>/imu_link</linkName>\n'
            f'  <imuTopic>/imu</imuTopic>\n{"".join(body)}</plugin>\n')
    return out, text
