"""
One entry per deviation kind: every per-kind property that :mod:`.api` and :mod:`.grid` read.

A new deviation is one :class:`Kind` in :data:`KIND` (its variance, '#', EDF and bias functions
live in its family module); nothing else dispatches on the kind's name.
"""

from dataclasses import dataclass
import functools
from typing import Callable, Optional

from . import allan_family, modified, theo, theobr, total
from ..allan.edf import edf_greenhall


def _no_bias(alpha, m, n_phase):
    """Bias factor 1: Stable32 prints the raw variance of this kind."""
    return 1.0


@dataclass(frozen=True)
class Kind:
    """
    What distinguishes one deviation kind from another.

    Attributes
    ----------
    name : str
        Its name (``deviation(kind=...)``).
    variance : callable
        ``(x, ms) -> (T, A)``: the uncorrected variance from the phase x (A, N) in sample
        units, numpy (the oracle of the compiled paths); tdev: MVAR (scaled afterwards).
    terms, edf, bias : callable
        ``(n_phase, m)``: summands behind the estimate (Stable32's '#');
        ``(alpha, m, n_phase)``: EDF; ``(alpha, m, n_phase)``: E[raw variance] / (the
        variance Stable32 prints) for noise alpha.
    stop_ratio : int
        Stable32's stop ratio: the default grid ends at m = n / stop_ratio (:mod:`.grid`).
    differences : int
        Most differences the lag-1 ACF noise identification may take (2 Allan-like, 3
        Hadamard-like, :func:`.noise_id.identify_phase`).
    alpha_range : tuple of int
        Noise exponents the EDF accepts (alpha + 2d > 1); identified alphas are clipped to it
        and a fixed alpha must lie in it.
    compiled : str or None
        Its compiled path: ``'allan'`` (the package's Allan kernel), ``'blocked'``
        (:func:`.kernels.variance`, from :data:`imu_allan.core.allan.estimate.SMALL_WORK` on),
        ``'windowed'`` (:func:`.total_kernel.variance`, always when numba is there).
    gathers_id_points : bool
        Its compiled pass also gathers the noise identification's points (non-overlapping
        strided sums: :func:`.kernels.strided_and_alpha`).
    tau_factor : float
        tau / (m tau0) (theo1: 0.75).
    m_step : int
        Averaging factors are multiples of it (theo1: even m), the shortest one included.
    edf_floor : bool
        Floor the EDF at 1 (why: :func:`.api.finish`).
    allan_grid : bool
        Default grid of ``allan_deviation`` (the ``min_clusters`` guard) instead of the stop
        ratio (oadev).
    run_bias : callable or None
        ``(x, avar, theo1) -> (alpha (A,), factor (A,))``: one noise type and bias factor per
        axis for the whole run instead of per averaging time (theo1: Stable32's ThêoBR,
        :mod:`.theobr`); used unless the caller fixes alpha.
    derived_from : str or None
        Computed as that kind's result, then scaled by ``scale(tau)`` (tdev: mdev x tau/sqrt 3).
    scale : callable or None
        ``tau (T,) -> (T,)``, with ``derived_from``.

    """

    name: str
    variance: Callable
    terms: Callable
    edf: Callable
    stop_ratio: int
    differences: int
    alpha_range: tuple
    bias: Callable = _no_bias
    compiled: Optional[str] = None
    gathers_id_points: bool = False
    tau_factor: float = 1.0
    m_step: int = 1
    edf_floor: bool = False
    allan_grid: bool = False
    run_bias: Optional[Callable] = None
    derived_from: Optional[str] = None
    scale: Optional[Callable] = None


def _greenhall(d, overlapping, modif):
    """EDF of a d-th difference variance (:func:`~..allan.edf.edf_greenhall`) as (alpha, m, N)."""
    def edf(alpha, m, n_phase):
        return edf_greenhall(int(alpha), d, int(m), int(n_phase), overlapping, modif)
    return edf


def _allan_family(name, stop_ratio, differences, alpha_range, compiled, **extra):
    return Kind(name, functools.partial(allan_family.variance_reference, name),
                functools.partial(allan_family.terms, name),
                _greenhall(*allan_family.edf_args(name)),
                stop_ratio, differences, alpha_range, compiled=compiled, **extra)


def _total_family(name, stop_ratio, differences, alpha_range, variance, compiled):
    return Kind(name, variance, functools.partial(total.terms, name),
                functools.partial(total.edf, name), stop_ratio, differences, alpha_range,
                bias=functools.partial(total.bias_factor, name), compiled=compiled,
                edf_floor=True)


def _theo1_bias(alpha, m, n_phase):
    """Theo1's bias for a known noise: 1 / b(alpha, m) (Howe & Tasset 2004, :func:`.theo.bias`)."""
    return 1.0 / theo.bias(alpha, m)


_ALLAN, _HADAMARD = (-2, 2), (-4, 2)
_MDEV = Kind('mdev', modified.variance_fast, modified.terms, _greenhall(2, True, True), 4, 2,
             _ALLAN, compiled='blocked')

#: Every kind, in the order :data:`.api.KINDS` lists them.
KIND = {kind.name: kind for kind in (
    _allan_family('adev', 5, 2, _ALLAN, 'blocked', gathers_id_points=True),
    _allan_family('oadev', 4, 2, _ALLAN, 'allan', allan_grid=True),
    _MDEV,
    Kind('tdev', modified.variance_fast, modified.terms, _MDEV.edf, 4, 2, _ALLAN,
         compiled='blocked', derived_from='mdev', scale=modified.tdev_scale),
    _allan_family('hdev', 5, 3, _HADAMARD, 'blocked', gathers_id_points=True),
    _allan_family('ohdev', 4, 3, _HADAMARD, 'blocked'),
    _total_family('totdev', 2, 2, _ALLAN, total.totvar, 'blocked'),
    _total_family('mtotdev', 3, 2, _ALLAN, total.mtotvar, 'windowed'),
    _total_family('htotdev', 3, 3, _HADAMARD, total.htotvar, 'windowed'),
    Kind('theo1', theo.theo1_fast, theo.terms, theo.edf, 1, 2, _ALLAN, bias=_theo1_bias,
         compiled='windowed', tau_factor=0.75, m_step=2, edf_floor=True,
         run_bias=theobr.run_bias),
)}


def kind_of(name):
    """Return the :class:`Kind` called ``name``; ValueError naming the known ones."""
    try:
        return KIND[name]
    except (KeyError, TypeError):
        raise ValueError(f'unknown deviation kind {name!r} (known: {", ".join(KIND)})') \
            from None
