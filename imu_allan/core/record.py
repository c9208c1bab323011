"""
The analysis of one record in one call: :func:`analyze_record` -> :class:`RecordAnalysis`.

Everything ``analyze`` computes about a recording is made here, from the samples read once
(:func:`imu_allan.formats.readers.read_samples`, a bag's temperatures with them): the estimate,
fit and verdicts (:class:`~.analysis.Analysis`), the recording advice and, as asked, the
denoised record's analysis, the dynamic Allan deviation with its change test, the bias slopes
against the temperature and the overbounding values of the consumers' noise models.  The
report modules render the result (report.json, console text, files); the command chooses what
to compute and what to write.  ROS-free and I/O-free, like the rest of ``core``.

Adding a part is one field of :class:`RecordAnalysis` (None when not computed), filled in
:func:`analyze_record`, and one renderer line (:data:`imu_allan.report.json_report.BLOCKS`).
Units are SI throughout; noise coefficients are continuous-time; times are s.
"""

from dataclasses import asdict, dataclass, field, replace
import math
from typing import TYPE_CHECKING

import numpy as np

from .analysis import Analysis, AnalysisOptions, analyze_samples
from .overbound import OverboundError
from ..errors import InputError

if TYPE_CHECKING:  # (imported where computed: the change test and the advisor load late)
    from .change.dynamic import DynamicResult
    from .fit.advisor import Advice


@dataclass(frozen=True)
class OverboundRequest:
    """
    The consumer models whose overbounding values to compute (``analyze --overbound``).

    ``models``: ``(shapes, over)`` pairs, ``shapes`` the model's terms (names of
    :data:`~.terms.TERMS`), ``over`` ``'axis'`` (one model per axis) or ``'sensor'`` (one
    model over the envelope of a sensor's axes, for consumers with one number per sensor).
    ``horizon_s``: the longest averaging time the bound holds for, s (None: the longest
    measured).  ``consumers``: ``(name, model, build)`` of the exporters whose values the
    ``overbound`` block describes (:func:`~.export_values.overbound_block`; none: no block),
    with the standard deviations multiplied by ``inflate = (white, walk)``.
    """

    models: tuple = ()
    horizon_s: float = None
    consumers: tuple = ()
    inflate: tuple = (1.0, 1.0)


@dataclass
class RecordOptions:
    """What :func:`analyze_record` computes (``analyze``'s options map onto these)."""

    #: the estimate, fit and checks
    analysis: AnalysisOptions = field(default_factory=AnalysisOptions)
    #: precision targets of the recording advice, term -> relative 68.3 % half-width
    #: (None: :data:`~.advisor.DEFAULT_TARGETS`)
    targets: dict = None
    #: dynamic Allan deviation: None (not computed), 0 (the default window) or a window, s
    dynamic_window_s: float = None
    #: also analyse the wavelet-denoised record (:func:`~.denoise.denoise`)
    denoise: bool = False
    #: overbounding values to compute (None: none)
    overbound: OverboundRequest = None


@dataclass
class DenoisedRecord:
    """The wavelet-denoised record and its analysis (same options as the record's)."""

    #: the analysed samples (``Analysis.t`` and ``.data``: after the warm-up cut), denoised
    #: (:class:`~imu_allan.formats.samples.Samples`, a layer above: not imported here)
    samples: object
    analysis: Analysis


@dataclass
class DynamicAnalysis:
    """
    The dynamic Allan deviation over sliding windows and the change test's findings.

    Times (``result.t``, the window centres; each change's ``t_s``, ``detected_s`` and
    ``extra['reported_s']``) count from the record's first sample, warm-up included; the
    windows cover the analysed samples only, from ``analysed_from_s`` on.
    """

    result: 'DynamicResult'
    #: :class:`~.change.detection.Change` list
    changes: list
    #: where the analysed samples start, s from the first sample (the warm-up)
    analysed_from_s: float = 0.0


@dataclass
class Coincidence:
    """A detected change or the warm-up, and the temperature move it falls in (if any)."""

    event: str               # 'change' or 'warmup'
    t_s: float               # s from the first IMU sample
    axis: str                # the change's axis (None for the warm-up)
    temperature_change: int  # index into TemperatureAnalysis.changes, None: none

    def to_json(self):
        """Return the report.json entry."""
        return asdict(self)


@dataclass
class TemperatureAnalysis:
    """
    Bias against temperature: the readings beside the record, the slopes and the moves.

    Slopes are SI per kelvin with 68.3 % intervals (:func:`~.temperature.bias_slopes`),
    regressed on every sample read, a warm-up the Allan estimate leaves out included (where
    the bias settles with the temperature, that is the signal).
    """

    topic: str
    #: readings: stamps, s (the Imu clock), and deg C
    t: np.ndarray
    celsius: np.ndarray
    #: (lowest, highest) deg C over the readings inside the record (all when none is)
    range_c: tuple
    #: axis -> :class:`~.temperature.SlopeEstimate`
    slopes: dict
    notes: list
    #: :class:`~.temperature.TemperatureChange` list, times from the first IMU sample
    changes: list
    coincidences: list = field(default_factory=list)


@dataclass
class OverboundValues:
    """
    Overbounding values of the requested consumer models (:mod:`.overbound`).

    ``fits``: ``(axes, shapes) -> OverboundFit``, ``axes`` one axis name or a tuple of a
    sensor's axes (their envelope), or the :class:`~.overbound.OverboundError` the overbound
    could not be made for: it is raised only where a consumer asks for it (:meth:`get`).
    """

    #: the horizon as asked, s (None: the longest measured averaging time)
    horizon_s: float
    fits: dict = field(default_factory=dict)
    #: report.json's ``overbound`` block (:func:`~.export_values.overbound_block`), None: none
    block: dict = None

    def get(self, axes, shapes):
        """Return the fit of ``shapes`` over ``axes``; None if not computed; raise its error."""
        key = (axes if isinstance(axes, str) else tuple(axes), tuple(shapes))
        fit = self.fits.get(key)
        if isinstance(fit, OverboundError):
            raise fit
        return fit


@dataclass
class RecordAnalysis:
    """
    Everything computed about one record, each part named; None where not asked or absent.

    ``analysis`` is the estimate (samples, timing, outliers, Allan deviation, fit, verdicts);
    the other parts are computed from it.
    """

    analysis: Analysis
    #: how much longer to record, on ``analyze``'s grid
    advice: 'Advice'
    denoised: DenoisedRecord = None
    dynamic: DynamicAnalysis = None
    temperature: TemperatureAnalysis = None
    overbound: OverboundValues = None

    @property
    def sensor(self):
        """Return the sensor's processing measured from the samples (``analysis.sensor``)."""
        return self.analysis.sensor

    @property
    def samples(self):
        """Return the record analysed (validated, warm-up included): ``analysis.samples``."""
        return self.analysis.samples


def analyze_record(samples, options=None, step=None):
    """
    Analyse one record; return a :class:`RecordAnalysis`; InputError for unusable data.

    ``samples``: :class:`~imu_allan.formats.samples.Samples` as read (SI), a bag's
    temperatures in ``samples.temperature``; ``options``: :class:`RecordOptions`; ``step``:
    called with the name of each stage as it starts (a progress display).
    """
    options = options or RecordOptions()
    step = step or (lambda _name: None)
    step('Allan deviation and fit')
    analysis = analyze_samples(samples, options.analysis)
    record = RecordAnalysis(analysis, record_advice(analysis, options))
    if options.denoise:
        step('denoising')
        record.denoised = denoised_record(analysis, options.analysis)
    if options.dynamic_window_s is not None:
        step('dynamic Allan deviation')
        record.dynamic = dynamic_analysis(analysis, options.dynamic_window_s)
    if analysis.samples.temperature is not None:
        record.temperature = temperature_analysis(analysis, record.dynamic)
    if options.overbound is not None:
        record.overbound = overbound_values(analysis, options.overbound)
    return record


def record_advice(analysis, options):
    """
    Return the :class:`~.advisor.Advice` of an analysis, on ``analyze``'s averaging grid.

    A record the motion verdict calls moving gets its moving axes in ``advice.moving``: its
    curve measures the motion, so the advice is to record at rest.
    """
    from .fit.advisor import advise, analysis_grid
    opts = options.analysis
    advice = advise(analysis.result, analysis.fit, options.targets,
                    analysis_grid(opts.points_per_decade, opts.min_clusters,
                                  opts.m_max(analysis.rate_hz)))
    if not analysis.static:
        advice.moving = [a for a, d in (analysis.motion or {}).items() if d.get('moving')]
    return advice


def denoised_record(analysis, options):
    """Denoise the analysed samples (``analysis.t``, ``.data``) and analyse them alike."""
    from .denoise import denoise
    samples = analysis.samples
    clean = denoise(analysis.data, analysis.rate_hz)
    # the analysed rows only: stamps and values agree (the extra columns and the
    # temperatures belong to the record read)
    den = replace(samples, t=analysis.t, data=clean, source=samples.source + ' (denoised)',
                  extra={}, temperature=None)
    return DenoisedRecord(den, analyze_samples(den, options))


def dynamic_analysis(analysis, window_s=None):
    """
    Return the dynamic Allan deviation of the analysed samples and its change test.

    ``window_s``: None or 0 for the default window.  InputError if the record is too short.
    Times are moved from the first analysed sample to the record's first sample.
    """
    from .change.detection import detect_changes
    from .change.dynamic import dynamic_allan
    try:
        dyn = dynamic_allan(analysis.data, analysis.rate_hz, window_s or None,
                            axes=analysis.axes)
    except ValueError as exc:
        raise InputError(analysis.source, f'--dynamic: {exc}') from None
    changes = detect_changes(dyn)
    start = analysis.warmup_s
    dyn.t = dyn.t + start
    for c in changes:
        c.t_s += start
        c.detected_s += start
        c.extra['reported_s'] += start
    return DynamicAnalysis(dyn, changes, start)


#: A change (or the warm-up) coincides with a temperature move within this fraction of the
#: record's duration.
COINCIDENCE_MARGIN = 0.05


def temperature_analysis(analysis, dynamic=None):
    """
    Bias slopes, temperature moves and coincidences, from ``analysis.samples.temperature``.

    ``dynamic`` (a :class:`DynamicAnalysis`, if computed) gives the changes to relate to the
    moves.
    """
    from .temperature import bias_slopes, temperature_changes
    samples = analysis.samples
    topic, t, celsius = samples.temperature
    imu_t = samples.t
    inside = (t >= imu_t[0]) & (t <= imu_t[-1])
    shown = celsius[inside] if inside.any() else celsius
    slopes, notes = bias_slopes(imu_t, np.asarray(samples.data, dtype=float),
                                analysis.rate_hz, analysis.axes, t, celsius)
    moves = temperature_changes(t - imu_t[0], celsius)
    part = TemperatureAnalysis(topic, t, celsius, (float(np.min(shown)), float(np.max(shown))),
                               slopes, list(notes), moves)
    changes = dynamic.changes if dynamic is not None else ()
    part.coincidences = coincidences(changes, analysis.warmup_s, moves,
                                     COINCIDENCE_MARGIN * float(analysis.duration_s))
    return part


def coincidences(changes, warmup_s, moves, margin_s):
    """
    Which detected changes and which warm-up coincide with a temperature move.

    A change (``t_s``, ``axis``; NaN times skipped) coincides with a move whose span holds its
    time, widened by ``margin_s``; a warm-up (``warmup_s`` > 0) with a move that starts
    before it ends (same margin).  Returns :class:`Coincidence` entries, changes first.
    """
    from .temperature import coinciding_change
    out = []
    for c in changes:
        if c.t_s is None or not math.isfinite(c.t_s):
            continue
        t_s = float(c.t_s)
        out.append(Coincidence('change', t_s, c.axis, coinciding_change(t_s, moves, margin_s)))
    if warmup_s:
        hit = next((i for i, m in enumerate(moves) if m.t_start_s <= warmup_s + margin_s), None)
        out.append(Coincidence('warmup', float(warmup_s), None, hit))
    return out


def overbound_values(fitted, request):
    """
    Overbound every model of ``request`` (an :class:`OverboundRequest`) on the fitted axes.

    ``fitted``: an Analysis or a FittedModel.  Per axis for ``over == 'axis'``, over each
    sensor's fitted axes for ``'sensor'``; a model that cannot be made is kept as its
    :class:`~.overbound.OverboundError` (:meth:`OverboundValues.get` raises it); with the
    request's consumers also report.json's ``overbound`` block (where one cannot be made, its
    error).  ValueError without a measured Allan deviation.
    """
    from .export_values import fit_of, overbound_block
    from .overbound import overbound_axes
    from .units import AXES, sensor_of
    fit = fit_of(fitted)
    if fit.result is None:
        raise ValueError('overbound needs the measured Allan deviation (a FittedModel from '
                         'fit_noise_model, or an Analysis)')
    axes = [a for a in AXES if a in fit.axes]
    values = OverboundValues(request.horizon_s)
    for shapes, over in request.models:
        shapes = tuple(shapes)
        if over == 'sensor':
            groups = [tuple(a for a in axes if sensor_of(a) == s) for s in ('gyro', 'accel')]
            targets = [g for g in groups if g]
        else:
            targets = axes
        for target in targets:
            key = (target, shapes)
            if key in values.fits:
                continue
            try:
                values.fits[key] = overbound_axes(fit.result, target, shapes, request.horizon_s)
            except OverboundError as exc:
                values.fits[key] = exc
    if request.consumers:
        values.block = overbound_block(fitted, values, request.consumers, request.inflate)
    return values
