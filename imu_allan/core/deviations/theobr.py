"""
ThêoBR: Stable32's automatic noise type and bias removal for Theo1, one per axis and run.

With the noise type left on automatic, Stable32 prints Theo1 (:mod:`.theo`) times one factor
derived from the data (Howe & Tasset, "Theo1: characterization of very long-term frequency
stability", EFTF 2004: the bias-removed ThêoBR; Taylor & Howe, "Fast ThêoBR", 2010):

    k = 1 / (n + 1) sum_{i=0}^{n} AVAR(m = 9 + 3 i) / Theo1(m = 12 + 4 i),  n = floor(N/6) - 3,

the mean ratio of the overlapping Allan variance to Theo1 at the same tau = (9 + 3 i) tau0, N
phase points; and it labels every averaging time with the one noise whose nominal ratio
AVAR / Theo1 is nearest to k (:data:`NOMINAL`, boundaries at geometric means).  The EDF is
then Theo1's for that noise (:func:`.theo.edf`).  A ratio whose AVAR has no term (2 m > N - 1,
when N is a multiple of 6) is left out.  Stable32's tables it reproduces, and what it is worth
on an IMU (the long end's factor is applied at the short end too; a caller who knows the noise
fixes alpha): docs/method.md section 8.

Cost: the exact mean takes Theo1 at N/6 factors, O(N^3) in all; above :data:`EXACT_WORK`
Theo1 summands per axis the mean is taken over :data:`SAMPLES` ratios evenly spaced in i,
each Theo1 with its window starts thinned to :data:`SAMPLE_WORK` summands (stride at most m/2,
:func:`.total_kernel.stride_for`), an estimate of the same mean (measured error in
``test/core/deviations/test_theobr.py``).
"""

import math

import numpy as np

#: Nominal AVAR / Theo1 per noise alpha (Stable32's, from Howe & Tasset's 2003 paper).
NOMINAL = {2: 0.4, 1: 0.6, 0: 1.0, -1: 1.71, -2: 2.24}
#: Theo1 summands per axis up to which the mean takes every ratio, exactly as Stable32.
EXACT_WORK = 1e8
#: Ratios and Theo1 summands per ratio of the estimated mean beyond :data:`EXACT_WORK`.
SAMPLES = 32
SAMPLE_WORK = 2e5


def factors(n_phase):
    """Averaging factors of the ratios: AVAR's 9 + 3i and Theo1's 12 + 4i, i = 0 .. n."""
    i = np.arange(max(n_phase // 6 - 3 + 1, 0))
    i = i[2 * (9 + 3 * i) <= n_phase - 1]  # AVAR needs a term
    return 9 + 3 * i, 12 + 4 * i


def _theo1_work(n_phase, m):
    return (n_phase - m) * (m // 2)


def plan(n_phase):
    """
    Return the ratios to average and Theo1's window-start stride for each: (m_avar, m_theo, s).

    Every ratio at stride 1 when their work fits :data:`EXACT_WORK`, else :data:`SAMPLES` of
    them evenly spaced in i, each Theo1 thinned to about :data:`SAMPLE_WORK` summands.
    """
    m_avar, m_theo = factors(n_phase)
    # Summed in float: exact below 2^53, and any larger total is far above EXACT_WORK.
    work = float(np.sum(_theo1_work(n_phase, m_theo), dtype=float))
    if work <= EXACT_WORK:
        return m_avar, m_theo, np.ones(m_theo.size, dtype=np.int64)
    pick = np.unique(np.round(np.linspace(0, m_theo.size - 1, SAMPLES)).astype(np.int64))
    m_avar, m_theo = m_avar[pick], m_theo[pick]
    stride = [min(max(1, math.ceil(_theo1_work(n_phase, int(m)) / SAMPLE_WORK)), m // 2)
              for m in m_theo]
    return m_avar, m_theo, np.array(stride, dtype=np.int64)


def ratio(x, avar, theo1):
    """
    ThêoBR's k per axis (A,) of the phase x (A, N); nan where no ratio exists.

    ``avar(x, ms)`` and ``theo1(x, ms, strides)`` return (T, A) variances (compiled or numpy:
    the caller's choice).
    """
    m_avar, m_theo, stride = plan(x.shape[1])
    if m_avar.size == 0:
        return np.full(x.shape[0], np.nan)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.mean(avar(x, m_avar) / theo1(x, m_theo, stride), axis=0)


def nominal_alpha(k):
    """Noise alpha (A,) whose nominal ratio is nearest k (geometric means); 0 where k is nan."""
    alphas = sorted(NOMINAL, reverse=True)  # ascending nominal ratio
    bounds = [math.sqrt(NOMINAL[a] * NOMINAL[b]) for a, b in zip(alphas, alphas[1:])]
    k = np.asarray(k, dtype=float)
    index = np.searchsorted(np.array(bounds), np.where(np.isfinite(k), k, 1.0))
    return np.array(alphas, dtype=int)[index]


def run_bias(x, avar, theo1):
    """
    Return alpha (A,) and the bias factor (A,) that divides the raw Theo1: 1 / k.

    Where k is undefined (fewer than 19 phase points, or no variation): white FM and no
    correction, Theo1 being unbiased for it.
    """
    k = ratio(x, avar, theo1)
    ok = np.isfinite(k) & (k > 0)
    safe = np.where(ok, k, 1.0)
    return nominal_alpha(safe), 1.0 / safe
