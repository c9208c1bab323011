"""
The offline analysis pipeline: validate, preprocess, Allan deviation, fit, verdicts.

ROS-free and I/O-free: it takes :class:`~imu_allan.formats.samples.Samples` and returns an
:class:`Analysis`; readers, report writers and the ``analyze`` command sit around it.  Every
problem with the data raises :class:`~imu_allan.errors.InputError` naming the source.
"""

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .allan.estimate import (
    allan_deviation,
    AllanResult,
    DEFAULT_MIN_CLUSTERS,
    DEFAULT_POINTS_PER_DECADE,
    tau_grid,
)
from .checks.preprocess import check_timing, OutlierReport, replace_outliers, TimingReport
from .checks.stamp_order import drop_isolated, without_dropped
from .checks.warmup import find_warmup
from .fit import fit_noise_model, FitError, FittedModel
from .sensor.measure import measure_sensor, SensorReport
from .units import is_gyro, physical_limits, sample_unit
from ..errors import InputError

#: Motion thresholds on 1-s block means, relative to the record's median: a still MEMS IMU's
#: 1-s averages wander by ~1e-4 rad/s and ~1e-3 m/s^2; a moving robot by orders more.
MOTION_GYRO_RAD_S = 0.02
MOTION_ACCEL_M_S2 = 0.2
#: A gap longer than this many nominal intervals (and 1 s) is a jump, not a dropped sample.
JUMP_INTERVALS = 100


@dataclass
class AnalysisOptions:
    """Knobs of :func:`analyze_samples` (command-line options map onto these)."""

    terms: list = None
    points_per_decade: float = DEFAULT_POINTS_PER_DECADE
    min_clusters: int = DEFAULT_MIN_CLUSTERS
    replace_outliers: bool = False
    tau_max: float = None
    rate_hz: float = None
    allow_jumps: bool = False
    online: bool = False
    #: export coefficients of a record the motion verdict calls moving (Kalibr, exporters)
    allow_motion: bool = False
    #: Deviation kinds to compute (:data:`imu_allan.core.deviations.KINDS`); ``oadev`` is the
    #: estimate the fit uses, the others go into :attr:`Analysis.deviations`.
    estimators: tuple = ('oadev',)
    #: measure the sensor's own processing (LSB, filter, lines) and fit where it does not
    #: shape the curve (:mod:`.sensor`, :mod:`.fit.tau_range`); False: the plain IEEE fit
    #: over every averaging time
    sensor: bool = True
    #: fit only these averaging times (s), (lo, hi); None: chosen from the data
    tau_range: tuple = None
    #: the device's filter window, s, when known (the 3DM-GX3-25's 0xDB window / 1 kHz);
    #: its filter then replaces the measured one in the fit
    filter_window_s: float = None

    def m_max(self, rate_hz):
        """Return the longest averaging factor ``tau_max`` allows at ``rate_hz`` (None: any)."""
        return None if self.tau_max is None else int(self.tau_max * rate_hz)


@dataclass
class Analysis:
    """
    The estimate of one record: Allan deviation, fit, and the verdicts on the data.

    Made by :func:`analyze_samples`; :class:`~.record.RecordAnalysis` holds it beside the
    other parts of a record's analysis (advice, dynamic, temperature, ...).
    """

    source: str
    axes: tuple
    n_samples: int
    rate_hz: float
    duration_s: float
    timing: TimingReport
    outliers: OutlierReport
    result: AllanResult
    fit: FittedModel
    static: bool
    motion: dict
    warnings: list = field(default_factory=list)
    #: The samples the estimate used, (n_samples, A), SI: the validated record after the
    #: warm-up cut (``warmup_s``), outliers replaced when asked.
    data: np.ndarray = None
    #: Their time stamps, (n_samples,), s: the rows of ``data``, the warm-up cut alike.  The
    #: whole record (warm-up included) is ``samples``.
    t: np.ndarray = None
    upper_limits: dict = field(default_factory=dict)
    integrity: str = ''
    warmup_s: float = 0.0  # start left out: the bias was settling (core/checks/warmup.py)
    allow_motion: bool = False
    #: Extra deviations asked for (``AnalysisOptions.estimators``): kind -> DeviationResult.
    deviations: dict = field(default_factory=dict)
    #: The record analysed: the input Samples as validated (isolated stamp faults dropped,
    #: with their warning; :mod:`.stamp_order`), before the warm-up cut; the input object
    #: itself when nothing was dropped.  Callers use it instead of applying the rule again.
    samples: object = None
    #: The sensor's own processing measured from ``data`` (None when not asked,
    #: ``AnalysisOptions.sensor``).
    sensor: Optional[SensorReport] = None


_VALIDATE_BLOCK = 1 << 16  # rows checked at a time


def _validate(samples):
    """
    Refuse records the estimator cannot use, naming the first offending sample.

    Returns the samples, without isolated out-of-order or repeated stamps (dropped with a
    warning by the rule the allan node applies, :mod:`.stamp_order`).
    """
    where = samples.source or 'input'
    if samples.n == 0:
        raise InputError(where, 'no samples')
    if samples.n < 2:
        raise InputError(where, 'only one sample; need a record to compute an Allan deviation')
    limits = np.asarray(physical_limits(samples.axes))
    with np.errstate(invalid='ignore'):  # (NaN compares False: it is caught too)
        # in blocks: no record-sized temporary; on a hit the whole record, to count and name
        if any((~(np.abs(samples.data[s:s + _VALIDATE_BLOCK]) <= limits)).any()
               for s in range(0, samples.n, _VALIDATE_BLOCK)):
            bad = ~(np.abs(samples.data) <= limits)
            i, j = np.argwhere(bad)[0]
            value, unit = samples.data[i, j], sample_unit(samples.axes[j])
            what = (f'non-finite value {value}' if not np.isfinite(value) else
                    f'non-physical value {value:.6g} (beyond {limits[j]:g} {unit})')
            raise InputError(where, f'{what} in {samples.axes[j]} at sample {i} '
                                    f'(t={samples.t[i]:.6f} s); {int(bad.any(axis=1).sum())} '
                                    'such sample(s): damaged input or wrong units')
    if not np.all(np.isfinite(samples.t)):
        raise InputError(where, f'non-finite time stamp at sample '
                                f'{int(np.flatnonzero(~np.isfinite(samples.t))[0])}')
    keep, problem = drop_isolated(samples.t)  # the node's rule (core/checks/stamp_order.py)
    if problem:
        back = np.flatnonzero(np.diff(samples.t) <= 0)
        i = int(back[0]) + 1
        raise InputError(where, f'time stamps do not increase: sample {i} (t={samples.t[i]:.9f} s)'
                                f' is not after sample {i - 1} (t={samples.t[i - 1]:.9f} s); '
                                f'{back.size} such step(s), not isolated ({problem})')
    return without_dropped(samples, keep)


def motion_verdict(data, axes, rate_hz):
    """
    Is the record static?  Compare 1-s block means with the record median per axis.

    Returns ``(static, details)``: details holds the 95th percentile excursion per axis (SI)
    and the threshold used.
    """
    block = max(int(round(rate_hz)), 1)
    n_blocks = data.shape[0] // block
    details = {}
    if n_blocks < 2:
        return True, details
    means = data[:n_blocks * block].reshape(n_blocks, block, -1).mean(axis=1)
    excursion = np.percentile(np.abs(means - np.median(means, axis=0)), 95.0, axis=0)
    for j, axis in enumerate(axes):
        limit = MOTION_GYRO_RAD_S if is_gyro(axis) else MOTION_ACCEL_M_S2
        details[axis] = {'excursion_p95': float(excursion[j]), 'threshold': limit,
                         'moving': bool(excursion[j] > limit)}
    return not any(d['moving'] for d in details.values()), details


def _checks(samples, rate, outliers):
    """Return ``(outliers, static, motion)``: the outlier count (unless given), motion verdict."""
    if outliers is None:
        outliers = replace_outliers(samples.data, samples.axes, replace=False)[1]
    return (outliers, *motion_verdict(samples.data, samples.axes, rate))


def analyze_samples(samples, options=None):
    """
    Run the whole analysis on one record; raise InputError for unusable data.

    The checks that do not feed the estimate (the outlier count, unless the outliers are
    replaced, and the motion verdict: several passes over the samples) run on a thread beside
    the estimate and the fit, which leave a core free for much of their time (0.2 s less on a
    10 h record).
    """
    options = options or AnalysisOptions()
    where = samples.source or 'input'
    samples = _validate(samples)
    warnings = list(samples.warnings)
    timing = check_timing(samples.t)
    rate = options.rate_hz or timing.rate_hz
    warnings += _timing_warnings(samples, timing, options.allow_jumps, where)
    data, t, outliers, warmup_s = _analysed_rows(samples, rate, options.replace_outliers,
                                                 warnings)
    n = data.shape[0]
    taus = _averaging_times(n, rate, options, where)
    pool = ThreadPoolExecutor(1, thread_name_prefix='imu_allan_checks')
    measured = (pool.submit(measure_sensor, data, rate, samples.axes)
                if options.sensor and not options.online else None)
    pending = pool.submit(_checks, samples, rate, outliers)
    pool.shutdown(wait=False)   # the thread ends with the checks
    sensor = None
    if options.online:  # the node's pipeline, its sensor measurement included
        from .live.online import run_online
        pipeline = run_online(data, rate, t=t, axes=samples.axes, sensor=options.sensor)
        result = pipeline.result()
        if result is None:
            raise InputError(where, "too short for the online estimator's shortest "
                                    'averaging time after the motion gate')
        sensor = pipeline.sensor_report() if options.sensor else None
    else:
        result = allan_deviation(data, rate, taus=taus,
                                 points_per_decade=options.points_per_decade,
                                 min_clusters=options.min_clusters, axes=samples.axes)
    from .deviations import extra_deviations
    deviations = extra_deviations(data, rate, options.estimators, samples.axes,
                                  options.points_per_decade, options.min_clusters)
    try:
        # With OHDEV asked for, its curve decides a rate random walk against a rate ramp
        # where the Allan fit alone cannot (core/fit/hadamard_check.py).
        sensor = measured.result() if measured is not None else sensor
        processing = (None if sensor is None else
                      sensor.processing(options.filter_window_s))
        fit = fit_noise_model(result, terms=options.terms, deviations=deviations,
                              processing=processing, tau_range=options.tau_range)
    except FitError as exc:
        raise InputError(where, str(exc)) from None
    outliers, static, motion = pending.result()
    if not static:
        moving = [a for a, d in motion.items() if d['moving']]
        warnings.append('the IMU was not static (' + ', '.join(moving) + ' moved): the Allan '
                        'deviation then measures the motion, not the sensor noise')
    return Analysis(source=where, axes=tuple(samples.axes), n_samples=n, rate_hz=rate,
                    duration_s=n / rate, timing=timing, outliers=outliers, result=result,
                    fit=fit, static=static, motion=motion, warnings=warnings, data=data,
                    t=t, upper_limits=_kalibr_upper_limits(fit), integrity=samples.integrity,
                    warmup_s=warmup_s, allow_motion=options.allow_motion,
                    deviations=deviations, samples=samples, sensor=sensor)


def _timing_warnings(samples, timing, allow_jumps, where):
    """Return the warnings on the time stamps' gaps and jitter; InputError for a jump."""
    warnings = []
    if timing.n_gaps:
        jump = timing.longest_gap_s > max(1.0, JUMP_INTERVALS * timing.nominal_dt)
        if jump and not allow_jumps:
            i = int(timing.gap_indices[np.argmax(np.diff(samples.t)[timing.gap_indices])])
            cause = f' (the reader: {samples.warnings[0]})' if samples.warnings else ''
            raise InputError(where, f'time stamps jump by {timing.longest_gap_s:.3f} s after '
                                    f'sample {i} (t={samples.t[i]:.6f} s){cause}; the Allan '
                                    f'deviation needs an unbroken record')
        warnings.append(f'{timing.n_gaps} gap(s) in the time stamps, about '
                        f'{timing.missing_samples} sample(s) missing (longest '
                        f'{timing.longest_gap_s:.4f} s); samples are treated as evenly spaced')
    if timing.jitter > 0.05:
        warnings.append(f'time-stamp jitter is {100 * timing.jitter:.1f} % of the sample '
                        f'interval; the device timer or a driver with even stamps helps')
    return warnings


def _analysed_rows(samples, rate, replace, warnings):
    """
    Return ``(data, t, outliers, warmup_s)``: the rows the estimate uses (SI, s).

    Outliers replaced when asked (``outliers`` is their report then, else None: counted on
    the checks' thread), the warm-up (s) cut: the settling start would pass for a random walk.
    A warning is appended to ``warnings`` for replaced outliers.
    """
    data, outliers = np.asarray(samples.data, dtype=float), None
    if replace:
        data, outliers = replace_outliers(samples.data, samples.axes, replace=True)
        outliers.replaced = bool(outliers.total)
        if outliers.total:
            warnings.append(f'{outliers.total} outlier(s) replaced (Tukey F=3): '
                            + ', '.join(f'{a} {c}' for a, c in outliers.counts.items() if c))
    t = samples.t
    warmup_s = find_warmup(data, rate, samples.axes)[0]
    if warmup_s:
        cut = int(round(warmup_s * rate))
        data, t = data[cut:], t[cut:]
    return data, t, outliers, warmup_s


def _averaging_times(n, rate, options, where):
    """Return the averaging times (s) up to ``options.tau_max`` (None: the default grid)."""
    needed = 2 * options.min_clusters
    if n < needed:
        raise InputError(where, f'record of {n} samples ({n / rate:.3g} s) is too short for '
                                f'any averaging time (needs at least {needed} samples)')
    if options.tau_max is None:
        return None
    longest = n / rate / options.min_clusters
    if options.tau_max > longest:
        raise InputError(where, f'record of {n / rate:.4g} s is too short for averaging '
                                f'times up to {options.tau_max:g} s (at most '
                                f'{longest:.4g} s with {options.min_clusters} clusters)')
    return tau_grid(n, options.points_per_decade, options.min_clusters,
                    m_max=options.m_max(rate)) / rate


def _kalibr_upper_limits(fit):
    """95 % upper limits of N and K on axes where the fit did not detect them (for Kalibr)."""
    limits = {}
    for axis in fit.axes:
        for term in ('white_noise', 'rate_random_walk'):
            value = fit.upper_limit(axis, term)
            if np.isfinite(value):
                limits.setdefault(axis, {})[term] = value
    return limits
