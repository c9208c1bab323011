"""
Overlapping Allan deviation with 68.3 % confidence intervals.

Estimator (thesis eq. 4.1; NIST SP1065 eq. 11): with rate samples y_k at interval tau0, phase
x_0 = 0, x_k = tau0 * (y_0 + ... + y_{k-1}) (N = n + 1 phase points) and tau = m tau0,

    AVAR(tau) = sum_{k=0}^{N-2m-1} (x_{k+2m} - 2 x_{k+m} + x_k)^2 / (2 tau^2 (N - 2m)),

the fully overlapping (stride 1) estimator, each axis de-meaned before the cumulative sum
(docs/method.md section 1).  Intervals: Greenhall EDF (:mod:`.edf`) for the noise type that
dominates each averaging time, chi-square quantiles at the 68.27 % level (section 2).
"""

from dataclasses import dataclass
import logging
import math

import numpy as np

from . import edf as _edf
from ..terms import ID_ALPHA, TERMS
from ..units import AXES

#: Fewest non-overlapping clusters allowed at the longest averaging time (tau_max = T / 10).
DEFAULT_MIN_CLUSTERS = 10
DEFAULT_POINTS_PER_DECADE = 10


@dataclass
class AllanResult:
    """
    Allan deviation of a record, per averaging time and axis.

    Attributes
    ----------
    tau : numpy.ndarray
        Averaging times, s, shape (T,).
    m : numpy.ndarray
        Averaging factors tau / tau0 (samples per cluster), shape (T,).
    avar, adev, ci_low, ci_high, edf : numpy.ndarray
        Shape (T, A): Allan variance (unit^2), deviation (unit: rad/s or m/s^2) and its 68.3 %
        interval, and the equivalent degrees of freedom of each estimate.
    alpha : numpy.ndarray
        Shape (T, A): power-law noise exponent used for the EDF.
    axes : tuple of str
        Axis names of the columns.
    rate_hz : float
        Sample rate, Hz.
    n_samples : int
        Record length behind the estimate, samples: the number of rate samples for the batch
        estimator; for the streaming estimator (gaps, excluded spans) the longest span any
        averaging time covers, which is what the EDF and a simulation of the same record use.

    """

    tau: np.ndarray
    m: np.ndarray
    avar: np.ndarray
    adev: np.ndarray
    ci_low: np.ndarray
    ci_high: np.ndarray
    edf: np.ndarray
    alpha: np.ndarray
    axes: tuple
    rate_hz: float
    n_samples: int

    @classmethod
    def from_avar(cls, m, avar, n_samples, rate_hz, axes=None, alpha=None):
        """
        Build a result (EDF, intervals) from Allan variances computed elsewhere.

        ``avar`` has shape (T, A) for averaging factors ``m`` (a 1-D array is one axis);
        ``n_samples`` is the number of rate samples behind each estimate (an int, or an array
        (T,) or (T, A) for estimators that use different spans per averaging time; the result
        keeps the largest).  ``alpha`` (T, A) overrides the noise identification.
        """
        m = np.atleast_1d(np.asarray(m, dtype=np.int64))
        avar = np.asarray(avar, dtype=float)
        if avar.ndim == 1:
            avar = avar[:, None]
        if avar.shape[0] != m.size:
            raise ValueError(f'avar has {avar.shape[0]} rows for {m.size} averaging factors')
        axes = tuple(axes) if axes is not None else AXES[:avar.shape[1]]
        tau = m / float(rate_hz)
        if alpha is None:
            alpha = identify_noise(tau, avar)
        n = np.broadcast_to(np.asarray(n_samples), avar.shape)
        edf = np.array([[_edf.edf_oadev(alpha[i, j], m[i], int(n[i, j]) + 1)
                         for j in range(avar.shape[1])] for i in range(m.size)])
        adev = np.sqrt(avar)
        low, high = _edf.chi2_interval(adev, edf)
        n_total = int(np.max(n)) if np.size(n) else 0
        return cls(tau, m, avar, adev, low, high, edf, alpha, axes, float(rate_hz), n_total)

    def axis_index(self, axis):
        """Column index of an axis name."""
        return self.axes.index(axis)


def min_record(min_clusters=DEFAULT_MIN_CLUSTERS):
    """Fewest samples for which :func:`tau_grid` has any averaging time (m = 1)."""
    return max(int(min_clusters), 2)


def log_grid(stop, points_per_decade):
    """Return unique integers from 1 to ``stop`` spaced ``points_per_decade`` per decade (log)."""
    if points_per_decade <= 0:
        raise ValueError('points_per_decade must be > 0')
    if stop < 1:
        return np.zeros(0, dtype=np.int64)
    count = int(math.floor(math.log10(stop) * points_per_decade)) + 1
    ms = np.unique(np.round(np.logspace(0.0, math.log10(stop), count)).astype(np.int64))
    return ms[ms >= 1]


def tau_grid(n_samples, points_per_decade=DEFAULT_POINTS_PER_DECADE,
             min_clusters=DEFAULT_MIN_CLUSTERS, m_max=None):
    """
    Log-spaced averaging factors m = 1 .. n / min_clusters (unique integers).

    The guard keeps at least ``min_clusters`` non-overlapping clusters at the longest averaging
    time (the common tau_max = T/10 rule); returns an empty array when even m = 1 fails it.
    ``m_max`` lowers the longest averaging factor further.
    """
    limit = int(n_samples // min_record(min_clusters))
    return log_grid(limit if m_max is None else min(int(m_max), limit), points_per_decade)


def _phase(data):
    """
    Phase per axis, shape (A, n + 1), in units of (sample value x samples).

    The cumulative sum of the de-meaned rate with x_0 = 0, along contiguous memory (down the
    columns of an (n, A) array it is strided and was the estimate's slowest step).
    """
    y = np.array(np.asarray(data, dtype=float).T, order='C')
    y -= y.mean(axis=1, keepdims=True)
    x = np.zeros((y.shape[0], y.shape[1] + 1))
    np.cumsum(y, axis=1, out=x[:, 1:])
    return x


def avar_reference(data, ms):
    """
    Overlapping AVAR (T, A) of rate samples ``data`` (n, A), in units of the samples squared.

    The numpy definition the compiled kernel is tested against: the Allan family's
    (:func:`imu_allan.core.deviations.allan_family.variance_reference`) on the phase.
    """
    from ..deviations.allan_family import variance_reference
    return variance_reference('oadev', _phase(data), ms)


#: Second differences (samples x axes x averaging times) below which the numpy reference is
#: used: it finishes (~150-300 M/s) before numba would be imported and the compiled kernel
#: loaded (0.5-1 s once per process), which decides the run time of short records (a
#: one-minute CSV at 100 Hz: ~1e6).
SMALL_WORK = 5e7


def avar_function(work):
    """
    Return the AVAR implementation for ``work`` second differences: numpy reference or compiled.

    Both take ``(data, ms)`` and return the same numbers; :mod:`.kernel` is imported on first
    use (short records never import numba).  Without numba the reference runs, with one log
    line saying so (docs/benchmarks.md: how much slower).
    """
    if work < SMALL_WORK:
        return avar_reference
    try:
        from . import kernel as allan_kernel
    except ImportError:
        if not _NO_NUMBA:
            _NO_NUMBA.append(True)
            logging.getLogger('imu_allan').warning(
                'numba is not installed: the numpy reference Allan estimator runs instead '
                '(slower; pip install numba, or apt install python3-numba, for the fast one)')
        return avar_reference
    return allan_kernel.avar


_NO_NUMBA = []


def avar_fast(data, ms):
    """Overlapping AVAR like :func:`avar_reference`, compiled and multi-threaded."""
    return avar_function(math.inf)(data, ms)


def identify_noise(tau, avar):
    """
    Power-law exponent alpha of the dominant noise at each (tau, axis).

    A non-negative least-squares fit of the five IEEE term shapes in relative error gives the
    contribution of each term; the exponent of the largest one is used.  Robust where the
    local slope of a noisy curve is not.
    """
    from ..fit.nnls import nnls_scaled
    tau = np.asarray(tau, dtype=float)
    avar = np.atleast_2d(avar)
    basis = np.column_stack([TERMS[t].id_shape(tau) for t in ID_ALPHA])
    alphas = np.array(list(ID_ALPHA.values()))
    out = np.zeros(avar.shape, dtype=int)
    for j in range(avar.shape[1]):
        y = avar[:, j]
        ok = np.isfinite(y) & (y > 0)
        if ok.sum() < 2:
            continue
        w = 1.0 / y[ok]
        coef = nnls_scaled(basis[ok] * w[:, None], np.ones(ok.sum()))
        contrib = basis * coef
        out[:, j] = alphas[np.argmax(contrib, axis=1)]
    return out


def checked_samples(data, rate_hz):
    """
    Return ``data`` as a float array (n_samples, n_axes); ValueError for what no estimator takes.

    A 1-D array is one axis; ``rate_hz`` must be a positive finite number and every sample
    finite (the estimators of :mod:`imu_allan.core.deviations` check the same way).
    """
    data = np.asarray(data, dtype=float)
    if data.ndim == 1:
        data = data[:, None]
    if data.ndim != 2:
        raise ValueError('data must have shape (n_samples, n_axes)')
    if not rate_hz or not math.isfinite(rate_hz) or rate_hz <= 0:
        raise ValueError('rate_hz must be a positive number')
    if not np.all(np.isfinite(data)):
        raise ValueError('data contain NaN or inf')
    return data


def allan_deviation(data, rate_hz, taus=None, points_per_decade=DEFAULT_POINTS_PER_DECADE,
                    min_clusters=DEFAULT_MIN_CLUSTERS, axes=None, fast=True):
    """
    Overlapping Allan deviation of rate samples with 68.3 % confidence intervals.

    Parameters
    ----------
    data : array_like
        Shape (n_samples,) or (n_samples, n_axes): rate samples (rad/s, m/s^2, ...).
    rate_hz : float
        Sample rate, Hz (tau0 = 1 / rate_hz).
    taus : array_like, optional
        Averaging times in s; each is rounded to a whole number of samples.  Default: a log grid
        of ``points_per_decade`` per decade from tau0 to n tau0 / ``min_clusters``.
    points_per_decade, min_clusters : float, int
        Grid density and the guard on the longest averaging time.
    axes : sequence of str, optional
        Column names (default: the first n_axes of the package axis order).
    fast : bool
        Use the compiled estimator for long records (:func:`avar_function`; identical to the
        numpy reference within rounding); False: always the numpy reference.

    Returns
    -------
    AllanResult

    """
    data = checked_samples(data, rate_hz)
    n = data.shape[0]
    if taus is None:
        ms = tau_grid(n, points_per_decade, min_clusters)
        if ms.size == 0:
            raise ValueError(f'{n} samples are too few for any averaging time '
                             f'(need at least {min_record(min_clusters)})')
    else:
        tau_in = np.atleast_1d(np.asarray(taus, dtype=float))
        ms = np.round(tau_in * rate_hz).astype(np.int64)
        if np.any(ms < 1):
            raise ValueError(f'averaging time {tau_in[ms < 1][0]:g} s is shorter than one '
                             f'sample ({1.0 / rate_hz:g} s)')
        if np.any(2 * ms > n):
            raise ValueError(f'averaging time {tau_in[2 * ms > n][0]:g} s needs at least '
                             f'{2 * int(ms[2 * ms > n][0])} samples, record has {n}')
        ms = np.unique(ms)
    avar_of = avar_function(data.size * ms.size) if fast else avar_reference
    avar = avar_of(data, ms)
    return AllanResult.from_avar(ms, avar, n, rate_hz, axes)
