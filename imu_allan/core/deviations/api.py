"""
``deviation()``: every frequency-stability deviation Stable32 has, with 68.3 % intervals.

What each kind computes is in its family module (:mod:`.allan_family`, :mod:`.modified`,
:mod:`.total`, :mod:`.theo`) and everything that sets the kinds apart is one entry of
:data:`.kinds.KIND`, which this module reads: it turns rate samples into the phase they share,
picks the averaging factors (:mod:`.grid`), identifies the noise per averaging time
(:mod:`.noise_id`; theo1 per run, :mod:`.theobr`), applies Stable32's bias corrections and
attaches each kind's EDF and chi-square interval (:func:`imu_allan.core.allan.edf.chi2_interval`,
SP1065 eq 45).
"""

from dataclasses import dataclass, replace

import numpy as np

from . import grid, noise_id, theo
from .kinds import KIND, kind_of
from ..allan import estimate as _allan
from ..allan.edf import chi2_interval
from ..units import AXES

KINDS = grid.KINDS


@dataclass
class DeviationResult:
    """
    One deviation of a record, per averaging time and axis.

    ``kind`` one of :data:`KINDS`; ``tau`` (T,) s (theo1: 0.75 m tau0) and ``m`` (T,) the
    averaging factors; ``dev``, ``ci_low``, ``ci_high`` (T, A): the deviation, bias-corrected
    as Stable32 prints it, in the rate's unit (rad/s, m/s^2; tdev: that unit x s), and its
    68.3 % chi-square interval; ``edf``, ``alpha`` (T, A): equivalent degrees of freedom and
    the identified noise exponent; ``n_terms`` (T,) the summands behind each estimate
    (Stable32's '#'); ``rate_hz`` in Hz; ``n_samples`` the rate samples of the record.
    """

    kind: str
    tau: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    n_terms: np.ndarray
    axes: tuple
    rate_hz: float
    n_samples: int

    def axis_index(self, axis):
        """Column index of an axis name."""
        return self.axes.index(axis)


def raw_variance(kind, x, ms, data=None, fast=True):
    """
    Uncorrected variance (T, A) of ``kind`` from the phase ``x`` (A, N) in sample units.

    tdev gives MVAR (scaled afterwards).  With ``fast``, the kind's compiled path
    (:attr:`.kinds.Kind.compiled`; oadev needs ``data`` (n, A) for the Allan kernel);
    ``fast=False`` or no numba: the kind's numpy variance.
    """
    spec = kind_of(kind)
    if fast and spec.compiled == 'allan' and data is not None:
        if _compiled(data.size * len(ms)):
            from ..allan import kernel as allan_kernel
            return allan_kernel.avar_phase(x, ms)  # the phase given, not integrated again
        return _allan.avar_function(data.size * len(ms))(data, ms)  # short or no numba
    if fast and spec.compiled == 'blocked' and x.size * len(ms) >= _allan.SMALL_WORK:
        try:
            from . import kernels
        except ImportError:  # no numba: the numpy version below
            pass
        else:
            return kernels.variance(kind, x, ms)
    if fast and spec.compiled == 'windowed':
        try:
            from . import total_kernel
        except ImportError:  # no numba: the numpy version (exact, slower)
            pass
        else:
            return total_kernel.variance(kind, x, ms)
    return spec.variance(x, ms)


def _compiled(work):
    """Whether ``work`` (samples x axes x averaging times) runs compiled: numba, and enough."""
    if work < _allan.SMALL_WORK:
        return False
    try:
        from .. import jit  # noqa: F401  (numba, optional)
    except ImportError:
        return False
    return True


def phase(data, ms):
    """
    Phase (A, n + 1) of the samples (n, A) that every kind and the noise identification share.

    Integrated once per call: compiled (:func:`..allan.kernel.phase_exact`) when the deviation
    runs compiled, numpy (``allan._phase``) otherwise; the two are equal bit for bit.
    """
    if _compiled(data.size * len(ms)):
        from ..allan import kernel as allan_kernel
        return allan_kernel.phase_exact(data)
    return _allan._phase(data)


def raw_and_alpha(kind, x, ms, data):
    """
    Raw variance (:func:`raw_variance`) and noise alpha (:func:`identify`), both (T, A).

    adev and hdev, compiled: one pass per axis for both (:func:`.kernels.strided_and_alpha`),
    their sums being cheaper than reading the phase twice.
    """
    spec = kind_of(kind)
    dmax, span = spec.differences, spec.alpha_range
    if spec.gathers_id_points and _compiled(x.size * len(ms)):
        from . import kernels
        return kernels.strided_and_alpha(kind, x, ms, dmax, span)
    raw = raw_variance(kind, x, ms, data)
    id_ms = np.maximum(np.round(ms * spec.tau_factor), 1).astype(np.int64)
    return raw, identify(x, id_ms, dmax, span)


def identify(x, ms, dmax, span):
    """Alpha (T, A) per averaging factor: :func:`.noise_id.identify_phase`, compiled if long."""
    if _compiled(x.size * len(ms)):
        from . import noise_id_kernel
        return noise_id_kernel.identify_phase(x, ms, dmax, span)
    return noise_id.identify_phase(x, ms, dmax, span)


def run_bias(kind, x, data, fast=True):
    """
    Return the run-wide alpha (A,) and bias factor (A,) of a kind that has one (theo1).

    Its AVAR and Theo1 ratios on the compiled paths of :func:`raw_variance` when ``fast``.
    """
    def avar(x, ms):
        return raw_variance('oadev', x, ms, data, fast)

    def theo1(x, ms, strides):
        if fast:
            try:
                from . import total_kernel
            except ImportError:
                pass
            else:
                return total_kernel.variance('theo1', x, ms, strides)
        return theo.theo1_fast(x, ms, strides)
    return kind_of(kind).run_bias(x, avar, theo1)


def n_terms(kind, n_phase, m):
    """Summands behind the estimate of ``kind`` at factor ``m`` (Stable32's '#')."""
    return kind_of(kind).terms(n_phase, m)


def bias_factor(kind, alpha, m, n_phase):
    """E[raw variance] / (variance Stable32 prints), by kind and noise; 1 where none."""
    return kind_of(kind).bias(alpha, m, n_phase)


def finish(kind, raw, ms, alpha, n_phase, factor=None):
    """
    Bias-corrected deviation, EDF and 68.3 % interval from the raw variance (T, A).

    ``factor`` (broadcast to (T, A)), when given, is the bias factor instead of the kind's
    per-noise one (theo1's run-wide ThêoBR factor, :func:`run_bias`).
    """
    spec = kind_of(kind)
    if factor is None:
        factor = np.array([[spec.bias(a, m, n_phase) for a in row]
                           for m, row in zip(ms, alpha)]).reshape(raw.shape)
    dev = np.sqrt(np.maximum(raw, 0.0) / np.broadcast_to(factor, raw.shape))
    dof = np.array([[spec.edf(a, m, n_phase) for a in row]
                    for m, row in zip(ms, alpha)], dtype=float).reshape(raw.shape)
    if spec.edf_floor:
        # SP1065's fitted EDFs go below 1 (even negative) at the longest factors, outside the
        # range they were fitted on: one degree of freedom there, the widest honest interval.
        dof = np.where(np.isfinite(dof), np.maximum(dof, 1.0), dof)
    dof = np.where(dof > 0, dof, np.nan)
    low, high = chi2_interval(dev, dof)
    return dev, low, high, dof


def _check(data, rate_hz, kind):
    """
    Return ``data`` as a float array (n, A), kind and rate checked (finiteness: :func:`_finite`).

    A NaN or inf sample makes every phase value NaN (the mean is NaN or inf), so the phase's
    last value tells whether to look at the samples at all: a separate pass over them (a
    boolean copy of the record) cost 10 ms of adev's 100 on 1.7 M x 6.
    """
    if kind not in KINDS:
        raise ValueError(f'unknown deviation kind {kind!r} (known: {", ".join(KINDS)})')
    if not rate_hz or not np.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError('rate_hz must be a positive number')
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    if data.ndim != 2:
        raise ValueError('data must have shape (n_samples, n_axes)')
    return data


def _finite(data, rate_hz, x):
    """Raise :func:`..allan.checked_samples`' error if the phase ``x`` shows a NaN or inf."""
    if not np.all(np.isfinite(x[:, -1])):
        _allan.checked_samples(data, rate_hz)  # raises unless huge finite samples overflowed


def _factors(kind, data, rate_hz, taus, points_per_decade, min_clusters):
    n = data.shape[0]
    if taus is None:
        ms = grid.default_ms(kind, n, points_per_decade, min_clusters)
        if ms.size == 0:
            raise ValueError(f'{n} samples are too few for any {kind} averaging time')
        return ms
    tau_in = np.atleast_1d(np.asarray(taus, dtype=float))
    ms = grid.ms_from_taus(kind, tau_in, rate_hz)
    low = kind_of(kind).m_step
    if np.any(ms < low):
        raise ValueError(f'averaging time {tau_in[ms < low][0]:g} s is shorter than the '
                         f'shortest {kind} averaging time '
                         f'({grid.tau_factor(kind) * low / rate_hz:g} s)')
    empty = np.array([n_terms(kind, n + 1, int(m)) < 1 for m in ms])
    if np.any(empty):
        raise ValueError(f'averaging time {tau_in[empty][0]:g} s is too long for {kind} on '
                         f'a record of {n} samples')
    return np.unique(ms)


def deviation(data, rate_hz, kind='oadev', taus=None, points_per_decade=10,
              min_clusters=_allan.DEFAULT_MIN_CLUSTERS, axes=None, alpha=None):
    """
    Frequency-stability deviation ``kind`` of rate samples with 68.3 % intervals.

    ``data`` (n_samples,) or (n_samples, n_axes): rate samples (rad/s, m/s^2, ...), i.e.
    fractional-frequency-like data (allantools ``data_type='freq'``); ``rate_hz`` in Hz
    (tau0 = 1 / rate_hz); ``kind`` one of :data:`KINDS`.  ``taus`` (s) are each rounded to a
    whole factor m (theo1: even m, tau = 0.75 m tau0); default: ``points_per_decade``
    log-spaced factors up to Stable32's stop ratio (:mod:`.grid`; oadev: the ``min_clusters``
    guard of ``allan_deviation``).  ``axes``: column names (default: the package axis order).

    ``alpha`` fixes the noise exponent for every averaging time and axis (Stable32's "Alpha";
    +2 white PM .. -2 random-walk FM, -4 for the Hadamard kinds): the bias corrections and
    EDFs are that noise's.  Default: identified from the data, per averaging time (lag-1
    autocorrelation, B1 ratio: :mod:`.noise_id`); theo1 per axis for the whole run, with
    Stable32's ThêoBR bias removal (:mod:`.theobr`).  Returns a :class:`DeviationResult`.
    """
    data = _check(data, rate_hz, kind)
    spec = kind_of(kind)
    alpha = _fixed_alpha(spec, alpha)
    ms = _factors(kind, data, rate_hz, taus, points_per_decade, min_clusters)
    n = data.shape[0]
    x = phase(data, ms)
    _finite(data, rate_hz, x)
    factor = None
    if alpha is not None:
        raw = raw_variance(kind, x, ms, data)
        alphas = np.full(raw.shape, alpha, dtype=int)
    elif spec.run_bias is not None:
        raw = raw_variance(kind, x, ms, data)
        run_alpha, run_factor = run_bias(kind, x, data)
        alphas = np.repeat(run_alpha[None, :], len(ms), axis=0)
        factor = run_factor[None, :]
    else:
        raw, alphas = raw_and_alpha(kind, x, ms, data)
    dev, low, high, dof = finish(kind, raw, ms, alphas, n + 1, factor)
    tau = ms * spec.tau_factor / float(rate_hz)
    axes = tuple(axes) if axes is not None else AXES[:data.shape[1]]
    counts = np.array([spec.terms(n + 1, int(m)) for m in ms], dtype=np.int64)
    result = DeviationResult(spec.derived_from or kind, tau, ms, dev, low, high, dof,
                             alphas, counts, axes, float(rate_hz), n)
    return derive(result, spec) if spec.derived_from else result


def _fixed_alpha(spec, alpha):
    """Return ``alpha`` as an int inside the kind's range, or None; ValueError otherwise."""
    if alpha is None:
        return None
    lo, hi = spec.alpha_range
    try:
        value = int(alpha)
        whole = value == alpha
    except (TypeError, ValueError, OverflowError):
        whole = False
    if not whole or not lo <= value <= hi:
        raise ValueError(f'alpha must be a whole number from {lo} to {hi} for {spec.name}, '
                         f'not {alpha!r}')
    return value


def derive(base, spec):
    """Scale a base kind's result (mdev) into its derived kind's (``spec``: tdev)."""
    scale = spec.scale(base.tau)[:, None]
    return replace(base, kind=spec.name, dev=base.dev * scale, ci_low=base.ci_low * scale,
                   ci_high=base.ci_high * scale)


def tdev_of(mdev):
    """
    TDEV from an MDEV result: the same estimate, EDF and noise, scaled by tau / sqrt(3).

    SP1065 eq 15; ``deviation(..., 'tdev')`` is this of ``deviation(..., 'mdev')`` with the
    same arguments, so a caller that wants both computes the modified variance once.
    """
    return derive(mdev, KIND['tdev'])


def parse_kinds(text, where='--estimators'):
    """Kinds named in a comma-separated ``text``, in order; InputError naming an unknown one."""
    from ...errors import InputError
    kinds = [k.strip().lower() for k in str(text).split(',') if k.strip()]
    for kind in kinds:
        if kind not in KINDS:
            raise InputError(where, f'unknown estimator {kind!r} (known: {", ".join(KINDS)})')
    if not kinds:
        raise InputError(where, 'names no estimator')
    return tuple(dict.fromkeys(kinds))


def extra_deviations(data, rate_hz, kinds, axes, points_per_decade, min_clusters):
    """
    Compute the deviations of ``kinds`` but oadev (the analysis' own): kind -> result.

    A kind the record is too short for is left out (the Allan estimate decides whether the
    record is usable at all).
    """
    out, modified = {}, None  # mdev and tdev share one modified variance (:func:`tdev_of`)
    for kind in kinds:
        base = 'mdev' if kind == 'tdev' else kind
        if kind == 'oadev':
            continue
        if base != 'mdev' or modified is None:
            try:
                result = deviation(data, rate_hz, base, points_per_decade=points_per_decade,
                                   min_clusters=min_clusters, axes=axes)
            except ValueError:
                continue
        else:
            result = modified
        if base == 'mdev':
            modified = result
        out[kind] = tdev_of(result) if kind == 'tdev' else result
    return out
