"""
A change test on the dynamic Allan variance, per axis, with a known false-alarm rate.

Each new window (``k`` blocks of :class:`~imu_allan.core.change.dynamic.BlockAllan`) is compared
with a *baseline*: the pooled terms of every block since the axis's last reset that is not in the
window (its EDF grows with its length).  An axis is tested once its baseline holds
:data:`BASELINE_WINDOWS` windows: with one only, the noise type read from the baseline's slope
(which sets both EDFs) is too noisy where flicker dominates (measured: docs/analyze.md,
"the change test"; test/core/test_dynamic.py keeps that case).  Two tests per window and axis:

* **spectrum**: at every averaging factor m, the ratio R = AVAR_window / AVAR_baseline of two
  independent chi-square estimates is F(nu_w, nu_b)-distributed when nothing changed (NIST
  SP1065 sec. 5.3: AVAR ~ sigma^2 chi^2_nu / nu, nu the Greenhall & Riley 2004 EDF of the
  overlapping AVAR, :func:`~imu_allan.core.allan.edf.edf_oadev`, for the power-law exponent alpha
  read from the baseline's own slope, capped at :data:`EDF_MAX`).  Two-sided p-value from the
  F distribution.
* **level**: D = mean(second half of the window) - mean(first half) has variance
  2 AVAR(W/2) (the Allan variance's definition); AVAR(W/2) is extrapolated from the baseline's
  three longest taus with the local slope + 1/2 clipped to [0, +1] (conservative).  z^2 is
  F(1, nu_b) distributed (the baseline's AVAR is itself an estimate).

The threshold is Bonferroni over the tests of a day: p_crit = target / (windows per day x
(M + 1)), M averaging factors, windows per day = 86400 / step.  Overlapping windows and
neighbouring factors are positively correlated, so the real rate is below the target; it is
*measured* by ``scripts/dynamic_false_alarms.py`` on 24 h of simulated static data
(:data:`MEASURED_FALSE_ALARMS_PER_DAY`, docs/analyze.md).

A detection names ``what`` changed: ``level`` when the level test fires; otherwise the term
whose Allan-variance shape (:mod:`imu_allan.core.terms`) best fits the excess AVAR_window -
AVAR_baseline over tau (weighted least squares, one amplitude): ``white_noise`` (1/tau),
``quantization`` (1/tau^2), ``bias_instability`` (flat), ``rate_random_walk`` (tau), or
``sinusoid`` (the bump A^2 sin^4(pi f0 tau) / (pi f0 tau)^2, peak at tau ~ 0.371 / f0, f0 on a
grid; one more parameter, so a BIC penalty ln M).  ``ratio`` is after / before of the
deviation at the tau where that term's share of the change is largest; for ``level`` it is the
step over the baseline Allan deviation at W/2 (and ``step`` the step itself, SI).  ``t_s`` is
the change point inside the window (maximum likelihood over block boundaries: resolution one
step); ``detected_s`` the end of the window that detected it.  After a detection the axis's
baseline restarts after that window.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from .dynamic import phase_count
from ..allan.edf import edf_oadev
from ..terms import (
    quantization_shape,
    random_walk_shape,
    sampled_flicker_shape,
    sinusoid_shape,
    white_shape,
)

#: Default target: false alarms per axis per day.
DEFAULT_TARGET_PER_DAY = 0.05
#: Measured by scripts/dynamic_false_alarms.py (docs/analyze.md): false alarms per axis per day
#: on simulated static records (thesis model + rate random walk, 100 Hz, two 24-h records of
#: 6 axes, seeds 2000 and 3000, default target and window): 0 in 12 axis-days (Poisson 95 %
#: upper bound 0.25).
MEASURED_FALSE_ALARMS_PER_DAY = 0.0
MEASURED_AXIS_DAYS = 12.0
SECONDS_PER_DAY = 86400.0
#: EDF cap: the chi-square model of an estimate is never trusted beyond ~4.5 % (sqrt(2/EDF)):
#: a sinusoid or a slightly non-power-law spectrum makes windows differ by a few percent,
#: which an uncapped EDF of 10^4..10^5 at short tau would call significant.
EDF_MAX = 1000.0
#: A detected change whose blocks after it show no spectral change at this p is a level step.
TRANSIENT_P = 1e-3
#: Windows of baseline an axis needs before its windows are tested (see the module docstring).
BASELINE_WINDOWS = 3
_SINE_GRID = 48  # frequencies tried for a sinusoid (log-spaced up to Nyquist)


@dataclass
class Change:
    """One detected change (times in s: from the first sample offline, stamps online)."""

    axis: str
    t_s: float
    what: str
    ratio: float
    detected_s: float
    p_value: float
    tau_s: float = math.nan
    extra: dict = field(default_factory=dict)

    def to_json(self):
        """Return the report.json entry (SI; NaN as None)."""
        out = {'axis': self.axis, 't_s': _num(self.t_s), 'what': self.what,
               'ratio': _num(self.ratio), 'detected_s': _num(self.detected_s),
               'p_value': _num(self.p_value), 'tau_s': _num(self.tau_s)}
        out.update({k: _num(v) for k, v in self.extra.items()})
        return out


def _num(v):
    return float(v) if v is not None and math.isfinite(v) else None


def _special():
    import scipy.special
    return scipy.special


class ChangeTest:
    """
    The sequential change test over blocks (ROS-free; stream or whole record).

    ``rate_hz`` in Hz; ``block_samples`` the block (step) length and ``ms`` the averaging
    factors of the blocks' sums (:func:`~imu_allan.core.change.dynamic.layout`); ``k`` blocks
    per window (even); ``target_per_day`` false alarms per axis per day (sets the threshold).
    """

    def __init__(self, rate_hz, block_samples, ms, k, axes, target_per_day=None):
        self.rate_hz = float(rate_hz)
        self.block = int(block_samples)
        self.ms = np.asarray(ms, dtype=np.int64)
        self.tau = self.ms / self.rate_hz
        self.k = int(k)
        self.axes = tuple(axes)
        self.target = DEFAULT_TARGET_PER_DAY if target_per_day is None else target_per_day
        n_m, n_a = self.ms.size, len(self.axes)
        windows_per_day = SECONDS_PER_DAY * self.rate_hz / self.block
        self.p_crit = self.target / (windows_per_day * (n_m + 1))
        self._win = [np.zeros((self.k, n_m, n_a)), np.zeros((self.k, n_m, n_a)),
                     np.zeros((self.k, n_a)), np.zeros((self.k, n_a))]
        self._win_start = np.full(self.k, np.nan)  # block start times in the ring
        self._n_in = 0  # blocks in the ring (<= k)
        self._head = 0  # ring index of the oldest block
        self.base_sum = np.zeros((n_m, n_a))
        self.base_cnt = np.zeros((n_m, n_a))
        self.base_blocks = np.zeros(n_a, np.int64)
        self.skip = np.zeros(n_a, np.int64)  # ring blocks not to pool (after a detection)
        self.blocks_seen = 0
        self._pending = {}  # axis -> a detection waiting for blocks after the change
        m = self.ms.astype(float)
        self._shapes = {'white_noise': white_shape(self.tau),
                        'quantization': quantization_shape(self.tau),
                        'bias_instability': sampled_flicker_shape(self.tau, self.rate_hz),
                        'rate_random_walk': random_walk_shape(self.tau, self.rate_hz)}
        f_lo = 0.371 / (self.tau[-1] * 2.0)
        self._freqs = np.geomspace(min(f_lo, self.rate_hz / 4), self.rate_hz / 2.0,
                                   _SINE_GRID)
        self._sines = np.array([sinusoid_shape(self.tau, f) for f in self._freqs])
        self._m2 = 2.0 * m * m

    @property
    def baseline_blocks(self):
        """Blocks of baseline an axis needs before its windows are tested."""
        return BASELINE_WINDOWS * self.k

    @property
    def window_s(self):
        """Window length, s."""
        return self.k * self.block / self.rate_hz

    def memory_bytes(self):
        """Bytes held (fixed)."""
        return sum(a.nbytes for a in self._win) + self.base_sum.nbytes * 2

    def push(self, blocks, starts=None):
        """
        Test the windows that end with each of ``blocks`` (:class:`Blocks`); return changes.

        ``starts`` (nb,): each block's start time (s); default: block index x step from the
        first sample.
        """
        changes = []
        for i in range(blocks.n):
            start = (starts[i] if starts is not None
                     else (blocks.first + i) * self.block / self.rate_hz)
            changes += self._one([a[i] for a in blocks.arrays()], float(start))
        return changes

    def _one(self, parts, start):
        k = self.k
        if self._n_in == k:  # the oldest block leaves the window: into the baseline
            h = self._head
            pool = self.skip == 0
            self.base_sum[:, pool] += self._win[0][h][:, pool]
            self.base_cnt[:, pool] += self._win[1][h][:, pool]
            self.base_blocks[pool] += 1
            self.skip[~pool] -= 1
            slot = h
            self._head = (h + 1) % k
        else:
            slot = (self._head + self._n_in) % k
            self._n_in += 1
        for ring, part in zip(self._win, parts):
            ring[slot] = part
        self._win_start[slot] = start
        self.blocks_seen += 1
        if self._n_in < k:
            return []
        end = start + self.block / self.rate_hz
        changes = [self._finish(j, end) for j in list(self._pending)
                   if self.blocks_seen - self._pending[j]['first_pure'] >= k // 2]
        ready = np.flatnonzero((self.base_blocks >= self.baseline_blocks) & (self.skip == 0))
        ready = [j for j in ready if j not in self._pending]
        if ready:
            self._test(ready, end)
        return changes

    def _ordered(self, j):
        """Ring arrays of axis ``j`` in time order: sums (k, M), counts, ysum (k,), ycount."""
        order = (self._head + np.arange(self.k)) % self.k
        s, c, ys, yc = self._win
        return s[order, :, j], c[order, :, j], ys[order, j], yc[order, j], \
            self._win_start[order]

    def _spectrum(self, j, a_w, w_cnt, frac=1.0):
        """Per-factor (a_b, nu_w, nu_b, p, good) of axis j against its baseline."""
        sp = _special()
        with np.errstate(invalid='ignore', divide='ignore'):
            a_b = self.base_sum[:, j] / self.base_cnt[:, j] / self._m2
        good = (w_cnt > 0) & (self.base_cnt[:, j] > 0) & (a_b > 0) & (a_w > 0)
        nan = np.full(self.ms.size, np.nan)
        if good.sum() < 2:
            return a_b, nan, nan, np.ones(self.ms.size), good & False
        alpha = _alphas(self.ms, a_b, good)
        nu_w, nu_b = (np.array([_edf(alpha[i], m, phase_count(int(counts[i]), m))
                                if good[i] else np.nan for i, m in enumerate(self.ms)])
                      for counts in (w_cnt, self.base_cnt[:, j]))
        good &= np.isfinite(nu_w) & np.isfinite(nu_b)
        r = np.where(good, a_w / np.where(good, a_b, 1.0), 1.0)
        nw, nb = np.where(good, nu_w, 1.0), np.where(good, nu_b, 1.0)
        p = np.where(good, 2.0 * np.minimum(sp.fdtrc(nw, nb, r), sp.fdtr(nw, nb, r)), 1.0)
        return a_b, nu_w, nu_b, p, good

    def _test(self, axes, end):
        """Test the window of each axis; a detection becomes pending (see :meth:`_finish`)."""
        w_sum, w_cnt = self._win[0].sum(axis=0), self._win[1].sum(axis=0)
        for j in axes:
            with np.errstate(invalid='ignore', divide='ignore'):
                a_w = w_sum[:, j] / w_cnt[:, j] / self._m2
            a_b, nu_w, nu_b, p, good = self._spectrum(j, a_w, w_cnt[:, j])
            if not good.any():
                continue
            p_level, sd_half = self._level(j, a_b, nu_b, good)
            best = int(np.argmin(p))
            if min(p[best], p_level) >= self.p_crit:
                continue
            s, c, ys, yc, starts = self._ordered(j)
            level = p_level < self.p_crit and p_level <= p[best]
            if level:
                cut = _level_split(ys, yc)
            else:
                cut = _scale_split(s[:, best], c[:, best], a_b[best] * self._m2[best],
                                   nu_w[best])
            before = ys[:max(cut, 1)].sum() / max(yc[:max(cut, 1)].sum(), 1)
            # The block at the cut may hold both sides: the estimate waits for blocks after it.
            self._pending[j] = {'level': level, 'p': min(p[best], p_level), 't_s': starts[cut],
                                'first_pure': self.blocks_seen - self.k + cut + 1,
                                'before': before, 'detected_s': end, 'sd_half': sd_half}
            self.skip[j] = self.k  # the window's blocks are not pooled into the baseline

    def _finish(self, j, end):
        """Name and size a pending change from the blocks wholly after it; reset the axis."""
        info = self._pending.pop(j)
        n_pure = min(self.blocks_seen - info['first_pure'], self.k)
        s, c, ys, yc, _ = self._ordered(j)
        s, c, ys, yc = s[-n_pure:], c[-n_pure:], ys[-n_pure:], yc[-n_pure:]
        axis = self.axes[j]
        level = info['level']
        if not level:
            cnt = c.sum(axis=0)
            with np.errstate(invalid='ignore', divide='ignore'):
                a_w = s.sum(axis=0) / cnt / self._m2
            a_b, nu_w, nu_b, p, good = self._spectrum(j, a_w, cnt)
            # A change seen in the window that held it but not in the spectrum after it is a
            # step of the mean (it raises the AVAR only of the terms that span it).
            level = p.min() > TRANSIENT_P
        if level:
            step = ys.sum() / max(yc.sum(), 1) - info['before']
            change = Change(axis, info['t_s'], 'level', abs(step) / info['sd_half'],
                            info['detected_s'], info['p'], self.window_s / 2.0,
                            {'step': float(step)})
        else:
            what, ratio, i_star, extra = self._classify(a_w, a_b, nu_w, nu_b, good)
            change = Change(axis, info['t_s'], what, ratio, info['detected_s'], info['p'],
                            float(self.tau[i_star]), extra)
        change.extra['reported_s'] = end
        self.base_sum[:, j] = 0.0
        self.base_cnt[:, j] = 0.0
        self.base_blocks[j] = 0
        self.skip[j] = self.k - n_pure  # the pure blocks start the new baseline
        return change

    def _level(self, j, a_b, nu_b, good):
        """
        Level test of axis j: (p, sd of the half-window deviation).

        z^2 = D^2 / (2 AVAR_b(W/2)) is F(1, nu_b)-distributed (AVAR_b an estimate with the
        EDF nu_b of the longest tau it is extrapolated from), not chi-square(1): a baseline
        of an hour has only a few degrees of freedom at W/10.
        """
        _, _, ys, yc, _ = self._ordered(j)
        h = self.k // 2
        n1, n2 = yc[:h].sum(), yc[h:].sum()
        top = np.flatnonzero(good)
        if n1 == 0 or n2 == 0 or top.size < 2:
            return 1.0, math.nan
        i1, i0 = top[-1], top[-2]
        slope = math.log(a_b[i1] / a_b[i0]) / math.log(self.ms[i1] / self.ms[i0])
        slope = min(max(slope + 0.5, 0.0), 1.0)  # never falling: a flicker floor at least
        avar_half = max(a_b[i] * (self.window_s / 2.0 / self.tau[i]) ** slope
                        for i in top[-3:])  # the longest three: one low estimate is no floor
        step = ys[h:].sum() / n2 - ys[:h].sum() / n1
        z = step / math.sqrt(2.0 * avar_half)
        return float(_special().fdtrc(1.0, nu_b[i1], z * z)), math.sqrt(avar_half)

    def _classify(self, a_w, a_b, nu_w, nu_b, good):
        """Name the term whose AVAR shape fits the excess best; (what, ratio, i*, extra)."""
        g = np.flatnonzero(good)
        excess = (a_w - a_b)[g]
        var = 2.0 * a_w[g] ** 2 / nu_w[g] + 2.0 * a_b[g] ** 2 / nu_b[g]
        w = 1.0 / var
        best = (math.inf, None, None, None)
        for name, shape in self._shapes.items():
            chi2, amp = _wls(excess, shape[g], w)
            if chi2 < best[0]:
                best = (chi2, name, amp * shape, {})
        penalty = math.log(max(g.size, 2))
        for f, shape in zip(self._freqs, self._sines):
            chi2, amp = _wls(excess, shape[g], w)
            if amp > 0 and chi2 + penalty < best[0]:
                best = (chi2 + penalty, 'sinusoid', amp * shape, {'frequency_hz': float(f)})
        _, what, fitted, extra = best
        share = np.where(good, np.abs(fitted) / np.where(good, a_b, 1.0), -1.0)
        i_star = int(np.argmax(share))
        ratio = math.sqrt(a_w[i_star] / a_b[i_star])
        return what, ratio, i_star, extra


def _wls(y, s, w):
    """Weighted least squares of y = c s: (chi2, c)."""
    den = float(np.sum(w * s * s))
    if den <= 0:
        return math.inf, 0.0
    c = float(np.sum(w * s * y)) / den
    return float(np.sum(w * (y - c * s) ** 2)), c


def _alphas(ms, avar, good):
    """Power-law alpha per factor from the local log-log slope mu of AVAR: alpha = -mu - 1."""
    alpha = np.zeros(ms.size, np.int64)
    g = np.flatnonzero(good)
    if g.size < 2:
        return alpha
    mu = np.gradient(np.log(avar[g]), np.log(ms[g].astype(float)))
    alpha[g] = np.clip(np.rint(-mu - 1.0), -2, 2).astype(np.int64)
    return alpha


def _edf(alpha, m, n_phase):
    """EDF on a 1/16-octave grid of lengths (rounded down: conservative; cache hits)."""
    m = int(m)
    n_terms = n_phase - 2 * m
    if n_terms < 1:
        return math.nan
    grid = int(2.0 ** (math.floor(16.0 * math.log2(n_terms)) / 16.0))
    return min(edf_oadev(int(alpha), m, max(grid, 1) + 2 * m), EDF_MAX)


def _scale_split(sums, counts, lam0, nu_w):
    """Block index inside the window where the AVAR most likely changed (GLR of a scale)."""
    total = counts.sum()
    best, cut = -math.inf, 0
    for c in range(sums.shape[0]):
        n_a, s_a = counts[c:].sum(), sums[c:].sum()
        if n_a <= 0 or lam0 <= 0:
            continue
        r = s_a / n_a / lam0
        nu_a = nu_w * n_a / total
        llr = nu_a * (r - 1.0 - math.log(r)) if r > 0 else -math.inf
        if llr > best:
            best, cut = llr, c
    return cut


def _level_split(ysum, ycount):
    """Block index inside the window where the mean most likely stepped (CUSUM maximum)."""
    means = np.where(ycount > 0, ysum / np.maximum(ycount, 1), 0.0)
    total_mean = ysum.sum() / max(ycount.sum(), 1)
    cusum = np.cumsum((means - total_mean) * ycount)
    cuts = np.abs(cusum[:-1]) / np.sqrt(np.maximum(np.arange(1, means.size) *
                                                   np.arange(means.size - 1, 0, -1), 1))
    return int(np.argmax(cuts)) + 1 if cuts.size else 0


def detect_changes(result, target_per_day=None):
    """Run :class:`ChangeTest` over a :class:`~imu_allan.core.change.dynamic.DynamicResult`."""
    test = ChangeTest(result.rate_hz, int(round(result.step_s * result.rate_hz)), result.ms,
                      result.k, result.axes, target_per_day)
    return test.push(result.blocks)
