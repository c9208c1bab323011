"""Noise models: which terms act on which axis, with continuous-time SI parameters.

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
"""

import copy
from dataclasses import dataclass, field
import math
import os

import yaml

from .units import ALL_TERMS, AXES, sensor_of, TERM_PARAMETERS


class ModelError(ValueError):
    """A model file or model dictionary is malformed."""


def _check_params(axis, term, params, where):
    if term not in TERM_PARAMETERS:
        raise ModelError(f'{where}: unknown noise term {term!r} for {axis} '
                         f'(known: {", ".join(ALL_TERMS)})')
    names = TERM_PARAMETERS[term]
    if names == ('value',):
        if isinstance(params, dict):
            params = params.get('value')
        params = {'value': params}
    if not isinstance(params, dict) or set(params) != set(names):
        raise ModelError(f'{where}: {axis}.{term} needs {", ".join(names)}')
    out = {}
    for name in names:
        try:
            value = float(params[name])
        except (TypeError, ValueError):
            raise ModelError(f'{where}: {axis}.{term}.{name} is not a number') from None
        if not math.isfinite(value) or value < 0:
            raise ModelError(f'{where}: {axis}.{term}.{name} must be finite and >= 0')
        out[name] = value
    if term == 'gauss_markov' and out['tau_c'] <= 0:
        raise ModelError(f'{where}: {axis}.gauss_markov.tau_c must be > 0')
    if term == 'sinusoid' and out['frequency_hz'] <= 0:
        raise ModelError(f'{where}: {axis}.sinusoid.frequency_hz must be > 0')
    return out


@dataclass
class NoiseModel:
    """Noise terms per axis: ``terms[axis][term] = {param: value}`` (SI, continuous time)."""

    terms: dict = field(default_factory=dict)
    rate_hz: float = None

    def __post_init__(self):
        """Validate and normalise the parameters."""
        checked = {}
        for axis, axis_terms in self.terms.items():
            if axis not in AXES:
                raise ModelError(f'model: unknown axis {axis!r} (known: {", ".join(AXES)})')
            checked[axis] = {t: _check_params(axis, t, p, 'model')
                             for t, p in (axis_terms or {}).items()}
        self.terms = checked

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
        return NoiseModel(terms, self.rate_hz)

    def subset(self, axes):
        """Return a copy restricted to the given axes (missing axes get no terms)."""
        return NoiseModel({a: copy.deepcopy(self.terms.get(a, {})) for a in axes}, self.rate_hz)

    def to_dict(self):
        """Plain dictionary in the model-file layout (per-axis form)."""
        out = {'axes': {}}
        if self.rate_hz:
            out['rate_hz'] = float(self.rate_hz)
        for axis in self.axes:
            out['axes'][axis] = {
                t: (p['value'] if tuple(p) == ('value',) else dict(p))
                for t, p in self.terms[axis].items()}
        return out

    @classmethod
    def from_dict(cls, data, where='model'):
        """Build from the model-file layout (sensor defaults, then per-axis overrides)."""
        if not isinstance(data, dict):
            raise ModelError(f'{where}: expected a mapping with gyro/accel/axes entries')
        unknown = set(data) - {'gyro', 'accel', 'axes', 'rate_hz', 'description', 'units'}
        if unknown:
            raise ModelError(f'{where}: unknown key(s) {", ".join(sorted(unknown))}')
        terms = {}
        for axis in AXES:
            sensor_terms = data.get(sensor_of(axis)) or {}
            axis_terms = (data.get('axes') or {}).get(axis) or {}
            merged = {**sensor_terms, **axis_terms}
            if merged:
                terms[axis] = {t: _check_params(axis, t, p, where) for t, p in merged.items()}
        for axis in (data.get('axes') or {}):
            if axis not in AXES:
                raise ModelError(f'{where}: unknown axis {axis!r}')
        rate = data.get('rate_hz')
        return cls(terms, float(rate) if rate else None)

    @classmethod
    def from_yaml(cls, path):
        """Load a model file; raise :class:`ModelError` naming the file on any problem."""
        try:
            with open(path, encoding='utf-8') as stream:
                data = yaml.safe_load(stream)
        except OSError as exc:
            raise ModelError(f'{path}: cannot read model file ({exc.strerror})') from None
        except yaml.YAMLError as exc:
            raise ModelError(f'{path}: not valid YAML ({str(exc).splitlines()[0]})') from None
        return cls.from_dict(data, where=str(path))

    def to_yaml(self, path, header=None):
        """Write the model file (with a comment header stating units)."""
        text = '# imu_allan noise model: continuous-time coefficients, SI units\n'
        if header:
            text += ''.join(f'# {line}\n' for line in header.splitlines())
        text += yaml.safe_dump(self.to_dict(), sort_keys=False)
        with open(path, 'w', encoding='utf-8') as stream:
            stream.write(text)


DATA_DIR = os.path.join(os.path.dirname(os.path.dirname(__file__)), 'data')


def thesis_gx3_25_model():
    """Measured 3DM-GX3-25 noise from the thesis (Tables 4.1/4.2 averages), SI units.

    Gyro ARW 1.98/1.97/2.07 deg/sqrt(h) and bias instability 31/31.66/36.66 deg/h; accel VRW
    0.05 m/s/sqrt(h) and bias instability 2.31/3.55/2.48 m/s/h; 100 Hz.
    """
    return NoiseModel.from_yaml(os.path.join(DATA_DIR, 'gx3_25_thesis.yaml'))
