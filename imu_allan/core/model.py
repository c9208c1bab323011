"""
Noise models: which terms act on which axis, with continuous-time SI parameters.

A :class:`NoiseModel` is what the simulator consumes, what the fit produces and what model
files hold.  Model file format (YAML, SI units, continuous time)::

    rate_hz: 100.0            # optional: the sample rate the model was measured at
    gyro:                     # defaults for gyro_x, gyro_y, gyro_z
      white_noise: 5.8e-4     # N, rad/s/sqrt(Hz)
      bias_instability: 1.5e-4
    accel:
      white_noise: 8.3e-4
    axes:                     # per-axis entries override the sensor defaults
      gyro_z:
        gauss_markov: {sigma: 1.0e-4, tau_c: 30.0}
        sinusoid: {amplitude: 1.0e-4, frequency_hz: 0.5}

Single-parameter terms take a number; ``gauss_markov`` takes ``sigma`` (stationary std) and
``tau_c`` (correlation time, s); ``sinusoid`` takes ``amplitude`` and ``frequency_hz``.

The run-to-run term ``turn_on_bias: {mean: ..., sigma: ...}`` (rad/s or m/s^2, per sensor or
per axis, :data:`imu_allan.core.terms.TURN_ON_BIAS`) states the constant bias drawn at each
start: it is not noise within a run (the simulator and the Allan variance ignore it), it is
what several runs of one configuration are compared with.
"""

import copy
from dataclasses import dataclass, field
import functools
import math
import os
import stat

from .terms import TERMS, TURN_ON_BIAS
from .units import ALL_TERMS, AXES, sensor_of, TERM_PARAMETERS
from ..errors import InputError


class ModelError(InputError):
    """
    A model or budget file (or model dictionary) is malformed.

    ``ModelError('file: problem')`` (one text) and ``ModelError(where, problem)`` both work.
    """

    def __init__(self, where, problem=None):
        """Split a single ``'where: problem'`` text, or take both parts."""
        if problem is None:
            where, _, problem = str(where).partition(': ')
            if not problem:
                where, problem = 'model', where
        super().__init__(where, problem)


#: Bounds of the model/budget file schema (one place; used by NoiseModel and NoiseBudget).
MAX_FILE_BYTES = 1 << 20  # a model file is a few hundred bytes; bounds /dev/zero and the like
MAX_PARAMETER = 1.0e6  # no SI noise parameter, correlation time (s) or frequency (Hz) is larger
MAX_RATE_HZ = 1.0e6


@functools.cache
def _strict_loader():
    """
    Return a SafeLoader that refuses duplicate keys (YAML would silently keep the last one).

    Built on first use: importing yaml costs 20 ms, and most commands read no model file.
    """
    import yaml

    class StrictLoader(yaml.SafeLoader):
        def construct_mapping(self, node, deep=False):
            seen = set()
            for key_node, _ in node.value:
                key = self.construct_object(key_node, deep=True)
                try:
                    duplicate = key in seen
                except TypeError:  # an unhashable key: the base class reports it
                    break
                if duplicate:
                    raise yaml.constructor.ConstructorError(
                        None, None,
                        f'duplicate key {key!r} (line {key_node.start_mark.line + 1})',
                        key_node.start_mark)
                seen.add(key)
            return super().construct_mapping(node, deep)
    return StrictLoader


def _kind(value):
    return {bool: 'true/false', str: 'text', list: 'a list', dict: 'a mapping',
            type(None): 'empty'}.get(type(value), type(value).__name__)


def read_yaml_file(path, what='model'):
    """
    Load a model or budget YAML file within the schema's bounds.

    Raises :class:`ModelError` naming the file: unreadable, a directory or special file,
    larger than :data:`MAX_FILE_BYTES`, binary, not valid YAML, duplicate keys, nested too
    deeply.
    """
    where = str(path)
    try:
        mode = os.stat(path).st_mode
        if not stat.S_ISREG(mode):  # a FIFO would block, /dev/zero would never end
            kind = 'a directory' if stat.S_ISDIR(mode) else 'not a regular file'
            raise ModelError(where, f'{kind} (a {what} file is expected)')
        with open(path, 'rb') as stream:
            raw = stream.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise ModelError(where, f'cannot read {what} file ({exc.strerror})') from None
    if len(raw) > MAX_FILE_BYTES:
        raise ModelError(where, f'larger than {MAX_FILE_BYTES // 1024} KiB: not a {what} file')
    if b'\0' in raw:
        raise ModelError(where, f'binary data, not a {what} file (YAML text expected)')
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise ModelError(where, f'not UTF-8 text at byte {exc.start}: not a {what} file') from None
    import yaml
    try:
        return yaml.load(text, Loader=_strict_loader())  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        raise ModelError(where, f'not valid YAML ({" ".join(str(exc).split())[:160]})') from None
    except RecursionError:
        raise ModelError(where, 'YAML nested too deeply') from None


def as_mapping(value, where, name):
    """Return ``value`` as a dict (None -> {}); raise ModelError if it is not a mapping."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ModelError(where, f'{name} must be a mapping (key: value), not {_kind(value)}')
    return value


def as_number(value, where, name, low=0.0, high=MAX_PARAMETER, low_open=False):
    """
    Return ``value`` as a finite float in [low, high] (or (low, high]); else ModelError.

    Numbers and numeric text (YAML 1.1 reads ``1e-4`` as text) are accepted; true/false,
    lists, mappings, NaN and infinities are not.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ModelError(where, f'{name} must be a number, not {_kind(value)}')
    try:
        number = float(value)
    except OverflowError:
        raise ModelError(where, f'{name} is too large') from None
    except ValueError:
        raise ModelError(where, f'{name} is not a number ({str(value)[:40]!r})') from None
    if not math.isfinite(number):
        raise ModelError(where, f'{name} must be finite')
    if number < low or (low_open and number == low) or number > high:
        need = 'a positive number' if low_open and low == 0 else f'a number >= {low:g}'
        raise ModelError(where, f'{name} = {number:g}: must be {need} and at most {high:g}')
    return number


def per_axis_entries(data, where, more_keys=()):
    """
    Return the layout model and budget files share, checked: ``{axis: {term: raw value}}``.

    Top level: ``gyro`` and ``accel`` (defaults for their three axes), ``axes`` (per-axis
    overrides), ``description`` and ``more_keys``; every section a mapping, axes known.
    """
    if not isinstance(data, dict):
        raise ModelError(where, f'expected a mapping with gyro/accel/axes entries, not '
                                f'{_kind(data)}')
    unknown = set(map(str, data)) - {'gyro', 'accel', 'axes', 'description', *more_keys}
    if unknown:
        raise ModelError(where, f'unknown key(s) {", ".join(sorted(unknown))[:120]}')
    sensors = {s: as_mapping(data.get(s), where, s) for s in ('gyro', 'accel')}
    per_axis = as_mapping(data.get('axes'), where, 'axes')
    for axis in per_axis:
        if axis not in AXES:
            raise ModelError(where, f'unknown axis {str(axis)[:40]!r} (known: '
                                    f'{", ".join(AXES)})')
    entries = {}
    for axis in AXES:
        merged = {**sensors[sensor_of(axis)],
                  **as_mapping(per_axis.get(axis), where, f'axes.{axis}')}
        if merged:
            entries[axis] = merged
    return entries


def _check_params(axis, term, params, where, rate_hz=None):
    """Validate one term's parameters against the schema; return ``{param: float}``."""
    if term not in TERM_PARAMETERS:
        raise ModelError(where, f'unknown noise term {str(term)[:40]!r} for {axis} '
                                f'(known: {", ".join(ALL_TERMS)})')
    names = TERM_PARAMETERS[term]
    if names == ('value',) and not isinstance(params, dict):
        params = {'value': params}
    params = as_mapping(params, where, f'{axis}.{term}')
    if set(params) != set(names):
        raise ModelError(where, f'{axis}.{term} needs {", ".join(names)}')
    label = {n: f'{axis}.{term}' if names == ('value',) else f'{axis}.{term}.{n}' for n in names}
    out = {name: as_number(params[name], where, label[name]) for name in names}
    position = TERMS[term].position   # tau_c (s) or frequency_hz (Hz) of a hump term
    if position and out[position] <= 0:
        raise ModelError(where, f'{axis}.{term}.{position} must be > 0')
    if term == 'sinusoid' and rate_hz and out['frequency_hz'] >= rate_hz / 2:
        raise ModelError(where, f'{axis}.sinusoid.frequency_hz = {out["frequency_hz"]:g} '
                                f'is not below the Nyquist frequency {rate_hz / 2:g} Hz '
                                f'(rate_hz {rate_hz:g})')
    return out


def _check_turn_on(axis, params, where):
    """Validate one axis's ``turn_on_bias`` entry; return ``{'mean': float, 'sigma': float}``."""
    params = as_mapping(params, where, f'{axis}.{TURN_ON_BIAS.name}')
    if set(params) != set(TURN_ON_BIAS.params):
        raise ModelError(where, f'{axis}.{TURN_ON_BIAS.name} needs '
                                f'{", ".join(TURN_ON_BIAS.params)}')
    return {'mean': as_number(params['mean'], where, f'{axis}.{TURN_ON_BIAS.name}.mean',
                              -MAX_PARAMETER),
            'sigma': as_number(params['sigma'], where, f'{axis}.{TURN_ON_BIAS.name}.sigma')}


@dataclass
class NoiseModel:
    """
    Noise terms per axis: ``terms[axis][term] = {param: value}`` (SI, continuous time).

    ``turn_on_bias[axis] = {'mean', 'sigma'}`` (SI) is the run-to-run constant bias, where the
    model states one (empty otherwise).
    """

    terms: dict = field(default_factory=dict)
    rate_hz: float = None
    turn_on_bias: dict = field(default_factory=dict)

    def __post_init__(self):
        """Validate and normalise the parameters."""
        checked = {}
        for axis, axis_terms in as_mapping(self.terms, 'model', 'terms').items():
            if axis not in AXES:
                raise ModelError('model', f'unknown axis {axis!r} (known: {", ".join(AXES)})')
            checked[axis] = {t: _check_params(axis, t, p, 'model', self.rate_hz) for t, p in
                             as_mapping(axis_terms, 'model', axis).items()}
        self.terms = checked
        turn_on = {}
        for axis, params in as_mapping(self.turn_on_bias, 'model', 'turn_on_bias').items():
            if axis not in AXES:
                raise ModelError('model', f'unknown axis {axis!r} (known: {", ".join(AXES)})')
            turn_on[axis] = _check_turn_on(axis, params, 'model')
        self.turn_on_bias = turn_on

    @property
    def axes(self):
        """Axis names present in the model, in the package's axis order."""
        return [a for a in AXES if a in self.terms]

    def value(self, axis, term, param='value'):
        """Return one parameter, or NaN when the term is absent."""
        return self.terms.get(axis, {}).get(term, {}).get(param, math.nan)

    def with_term(self, axis, term, params):
        """Return a copy with ``term`` set (or replaced) on ``axis``."""
        terms = copy.deepcopy(self.terms)
        terms.setdefault(axis, {})[term] = params
        return NoiseModel(terms, self.rate_hz, copy.deepcopy(self.turn_on_bias))

    def subset(self, axes):
        """Return a copy restricted to the given axes (missing axes get no terms)."""
        return NoiseModel({a: copy.deepcopy(self.terms.get(a, {})) for a in axes}, self.rate_hz,
                          {a: dict(self.turn_on_bias[a]) for a in axes
                           if a in self.turn_on_bias})

    def to_dict(self):
        """Plain dictionary in the model-file layout (per-axis form)."""
        out = {'axes': {}}
        if self.rate_hz:
            out['rate_hz'] = float(self.rate_hz)
        for axis in [a for a in AXES if a in self.terms or a in self.turn_on_bias]:
            out['axes'][axis] = {
                t: (p['value'] if tuple(p) == ('value',) else dict(p))
                for t, p in self.terms.get(axis, {}).items()}
            if axis in self.turn_on_bias:
                out['axes'][axis][TURN_ON_BIAS.name] = dict(self.turn_on_bias[axis])
        return out

    @classmethod
    def from_dict(cls, data, where='model'):
        """Build from the model-file layout (sensor defaults, then per-axis overrides)."""
        where = str(where)
        entries = per_axis_entries(data, where, ('rate_hz', 'units'))
        rate = data.get('rate_hz')
        if rate is not None:
            rate = as_number(rate, where, 'rate_hz', 0.0, MAX_RATE_HZ, low_open=True)
        turn_on = {axis: _check_turn_on(axis, merged.pop(TURN_ON_BIAS.name), where)
                   for axis, merged in entries.items() if TURN_ON_BIAS.name in merged}
        terms = {axis: {t: _check_params(axis, t, p, where, rate) for t, p in merged.items()}
                 for axis, merged in entries.items() if merged}
        return cls(terms, rate, turn_on)

    @classmethod
    def from_yaml(cls, path):
        """Load a model file; raise :class:`ModelError` naming the file on any problem."""
        return cls.from_dict(read_yaml_file(path, 'model'), where=str(path))

    def to_yaml(self, path, header=None):
        """Write the model file (with a comment header stating units)."""
        text = '# imu_allan noise model: continuous-time coefficients, SI units\n'
        if header:
            text += ''.join(f'# {line}\n' for line in header.splitlines())
        import yaml
        text += yaml.safe_dump(self.to_dict(), sort_keys=False)
        with open(path, 'w', encoding='utf-8') as stream:
            stream.write(text)


DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(__file__)), 'data')


def thesis_gx3_25_model():
    """
    Measured 3DM-GX3-25 noise from the thesis (Tables 4.1/4.2 averages), SI units.

    Gyro ARW 1.98/1.97/2.07 deg/sqrt(h) and bias instability 31/31.66/36.66 deg/h; accel VRW
    0.05 m/s/sqrt(h) and bias instability 2.31/3.55/2.48 m/s/h; 100 Hz.
    """
    return NoiseModel.from_yaml(os.path.join(DATA_DIR, 'gx3_25_thesis.yaml'))
