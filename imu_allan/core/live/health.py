"""
IMU health: fitted noise coefficients against a noise budget, plus stamp checks.

ROS-free.  The allan node turns the :class:`Health` records built here into
``diagnostic_msgs/DiagnosticStatus`` entries on ``/diagnostics``; tests and offline tools use
them directly.

Levels follow ``diagnostic_msgs/DiagnosticStatus``: 0 OK, 1 WARN, 2 ERROR, 3 STALE.

Budget rule (per axis and resolved budgeted term, lo the lower end of its 68.3 % interval or,
lower still, :meth:`~imu_allan.core.fit.FittedModel.alarm_low`): ERROR when lo > error_ratio x
budget, WARN when lo > warn_ratio x budget, else OK.  Using a lower end means a level is
raised only when the data show the budget is missed, not when a short record merely cannot
yet prove that it is met.  A term not resolved raises no level: its upper limit is reported.

Budget file format (YAML, continuous-time SI units as in :mod:`imu_allan.core.units`)::

    warn_ratio: 1.0
    error_ratio: 2.0
    gyro:  {white_noise: 5.2e-4, bias_instability: 8.7e-5}
    accel: {white_noise: 7.8e-4, bias_instability: 3.9e-4}
    axes:  {gyro_z: {bias_instability: 1.0e-4}}   # optional per-axis overrides
"""

from dataclasses import dataclass, field
import math
import os

import numpy as np

from ..checks.stamp_order import keep_increasing
from ..model import as_number, DATA_DIR, ModelError, per_axis_entries, read_yaml_file
from ..units import AXES, conventional, IEEE_TERMS, si_unit

OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: Names of the levels (diagnostic_msgs/DiagnosticStatus), for people.
LEVEL_NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}

#: The packaged 3DM-GX3-25 datasheet budget.
DEFAULT_BUDGET_FILE = os.path.join(DATA_DIR, 'gx3_25_budget.yaml')


@dataclass
class Health:
    """One diagnostic record: a name, a level (0-3), a one-line message and key-values."""

    name: str
    level: int
    message: str
    values: dict = field(default_factory=dict)


@dataclass
class NoiseBudget:
    """Per-axis limits ``limits[axis][term]`` (SI) with the WARN / ERROR ratios."""

    limits: dict
    warn_ratio: float = 1.0
    error_ratio: float = 2.0
    source: str = ''

    @classmethod
    def from_dict(cls, data, where='budget'):
        """
        Build from the file layout (the schema of :mod:`imu_allan.core.model`).

        Raises :class:`~imu_allan.core.model.ModelError` (an InputError) naming ``where``.
        """
        where = str(where)
        entries = per_axis_entries(data, where, ('warn_ratio', 'error_ratio'))
        ratios = {key: as_number(data.get(key, default), where, key, low_open=True)
                  for key, default in (('warn_ratio', 1.0), ('error_ratio', 2.0))}
        if ratios['error_ratio'] < ratios['warn_ratio']:
            raise ModelError(where, 'error_ratio must be >= warn_ratio')
        limits = {}
        for axis, merged in entries.items():
            for term in merged:
                if term not in IEEE_TERMS:
                    raise ModelError(where, f'{axis}: unknown or unbudgetable term '
                                            f'{str(term)[:40]!r} (known: {", ".join(IEEE_TERMS)})')
            limits[axis] = {term: as_number(value, where, f'{axis}.{term}', low_open=True)
                            for term, value in merged.items()}
        if not limits:
            raise ModelError(where, 'budget names no term for any axis')
        return cls(limits, ratios['warn_ratio'], ratios['error_ratio'], where)

    @classmethod
    def from_yaml(cls, path=None):
        """Load a budget file (default: the packaged 3DM-GX3-25 datasheet budget)."""
        path = path or DEFAULT_BUDGET_FILE
        return cls.from_dict(read_yaml_file(path, 'budget'), where=str(path))

    def limit(self, axis, term):
        """Budget of a term on an axis, or NaN when not budgeted."""
        return self.limits.get(axis, {}).get(term, math.nan)

    def level(self, axis, term, value, low):
        """
        Return the level a resolved term raises: WARN or ERROR once its lower end is over.

        ``value``, ``low``: the estimate and its interval's lower end (SI; NaN for a term not
        resolved, which raises nothing).  Without an interval the point value is all we have.
        """
        low_end = low if math.isfinite(low) else value
        limit = self.limit(axis, term)
        if low_end > self.error_ratio * limit:
            return ERROR
        return WARN if low_end > self.warn_ratio * limit else OK


def _fmt(value):
    return f'{value:.3g}' if math.isfinite(value) else 'nan'


def budget_health(coeffs, budget, axes=AXES, prefix='', limits=None, alarm_lows=None):
    """
    Compare a coefficient table with a budget; one :class:`Health` per axis (module docstring).

    ``coeffs`` (len(axes), 5, 3): ``[axis, term, (value, ci_low, ci_high)]`` in the order of
    :data:`~imu_allan.core.units.IEEE_TERMS`, SI, NaN where a term is not resolved (the
    ``imu/allan_coeffs`` layout); None: no estimate yet, every axis STALE.  ``limits`` and
    ``alarm_lows`` (len(axes), 5), SI: the 95 % upper limits of the terms not resolved (the
    ``imu/allan_coeffs`` limit block; "within budget" once below it) and the lower ends the
    levels rest on.  ``prefix``: of the status names (node name and colon).

    Values per budgeted term: ``<term>`` (measured), ``<term>.ci_low``, ``.ci_high``,
    ``.alarm_low``, ``.budget``, ``.ratio`` (measured / budget), ``.upper_limit`` (not
    resolved), ``.unit`` (SI) and ``.conventional`` (value in datasheet units).
    """
    out = []
    for i, axis in enumerate(axes):
        name = f'{prefix}{axis} noise'
        terms = budget.limits.get(axis, {})
        if coeffs is None:
            out.append(Health(name, STALE, 'no estimate yet (collecting still samples)',
                              {f'{t}.budget': v for t, v in terms.items()}))
            continue
        level, problems, notes, values = OK, [], [], {}
        for term, limit in terms.items():
            j = IEEE_TERMS.index(term)
            value, low, high = (float(v) for v in coeffs[i, j])
            upper = math.nan if limits is None else float(limits[i, j])
            values[term] = value
            values[f'{term}.ci_low'] = low
            values[f'{term}.ci_high'] = high
            values[f'{term}.budget'] = limit
            values[f'{term}.ratio'] = value / limit if math.isfinite(value) else math.nan
            values[f'{term}.upper_limit'] = upper
            values[f'{term}.unit'] = si_unit(axis, term)
            if not math.isfinite(value):  # not resolved: a limit, never a level
                if math.isfinite(upper):
                    conv, unit = conventional(axis, term, upper)
                    notes.append(f'{term} < {_fmt(conv)} {unit} (95 %)'
                                 + (': within budget' if upper <= limit else
                                    ': not resolved yet'))
                continue
            conv, unit = conventional(axis, term, value)
            values[f'{term}.conventional'] = f'{conv:.4g} {unit}'
            alarm = low if alarm_lows is None else min(low, float(alarm_lows[i, j]))
            values[f'{term}.alarm_low'] = alarm
            term_level = budget.level(axis, term, value, alarm)
            if term_level > OK:
                problems.append(f'{term} {_fmt(value)} [{_fmt(low)}, {_fmt(high)}] '
                                f'{si_unit(axis, term)} exceeds budget {_fmt(limit)} '
                                f'({value / limit:.2f}x)')
            level = max(level, term_level)
        if level > OK:
            message = '; '.join(problems)
        else:
            resolved = [t for t in terms if math.isfinite(values.get(t, math.nan))]
            message = '; '.join((['within budget (' + ', '.join(resolved) + ')']
                                 if resolved else []) + notes) or 'no budgeted term resolved yet'
        out.append(Health(name, level, message, values))
    return out


class StampMonitor:
    """
    Header-stamp checks on a sample stream: order, gaps and rate (bounded memory).

    Out-of-order or repeated stamps (not later than the last kept one) are dropped.  A gap is a
    spacing above ``gap_factor`` sample intervals: the samples on both sides are kept, but the
    Allan estimate restarts its phase there (missing samples would otherwise shift it).
    """

    def __init__(self, rate_hz, gap_factor=1.5):
        """``rate_hz``: configured sample rate, Hz; ``gap_factor``: gap threshold in intervals."""
        if not rate_hz or rate_hz <= 0:
            raise ValueError('rate_hz must be > 0')
        self.rate_hz = float(rate_hz)
        self.gap_factor = float(gap_factor)
        self.last_t = None
        self.first_t = None
        self.n_kept = 0
        self.out_of_order = 0
        self.gaps = 0
        self.max_gap_s = 0.0
        # Counters since the last call to :meth:`take_recent` (for "recent" diagnostics).
        self._recent = {'n': 0, 't0': None, 't1': None, 'gaps': 0, 'out_of_order': 0}

    def check(self, t):
        """
        Check stamps ``t`` (s, shape (n,)); return ``(keep, break_before)`` boolean arrays.

        ``break_before[i]`` marks a kept sample that follows a gap.
        """
        t = np.asarray(t, dtype=float)
        n = t.size
        if n == 0:
            return np.zeros(0, bool), np.zeros(0, bool)
        last = -math.inf if self.last_t is None else self.last_t
        keep = keep_increasing(t, last)  # the rule analyze applies too (checks/stamp_order.py)
        kept_t = t[keep]
        break_before = np.zeros(n, bool)
        if kept_t.size:
            prev = np.concatenate(([last], kept_t[:-1]))
            dt = kept_t - prev
            gap = np.isfinite(dt) & (dt > self.gap_factor / self.rate_hz)
            break_before[np.flatnonzero(keep)[gap]] = True
            n_gap = int(gap.sum())
            self.gaps += n_gap
            self._recent['gaps'] += n_gap
            if n_gap:
                self.max_gap_s = max(self.max_gap_s, float(dt[gap].max()))
            if self.first_t is None:
                self.first_t = float(kept_t[0])
            if self._recent['t0'] is None:
                self._recent['t0'] = float(kept_t[0])
            self._recent['t1'] = float(kept_t[-1])
            self._recent['n'] += int(kept_t.size)
            self.last_t = float(kept_t[-1])
            self.n_kept += int(kept_t.size)
        dropped = int(n - keep.sum())
        self.out_of_order += dropped
        self._recent['out_of_order'] += dropped
        return keep, break_before

    def measured_rate(self):
        """Mean sample rate over the whole run from the kept stamps (Hz), NaN if unknown."""
        if self.n_kept < 2 or self.last_t <= self.first_t:
            return math.nan
        return (self.n_kept - 1) / (self.last_t - self.first_t)

    def take_recent(self):
        """Return and reset the counters since the previous call (rate over that span)."""
        r = self._recent
        span = (r['t1'] - r['t0']) if r['t0'] is not None else 0.0
        rate = (r['n'] - 1) / span if r['n'] >= 2 and span > 0 else math.nan
        out = {'samples': r['n'], 'rate_hz': rate, 'gaps': r['gaps'],
               'out_of_order': r['out_of_order']}
        # The next span starts at the last stamp seen, so consecutive spans tile the run.
        self._recent = {'n': 1 if r['t1'] is not None else 0, 't0': r['t1'], 't1': r['t1'],
                        'gaps': 0, 'out_of_order': 0}
        return out


#: Seconds of header stamps whose median spacing fixes a measured rate (tau0).
RATE_SETTLE_S = 2.0


class RateFinder:
    """
    Measures a stream's sample rate from its header stamps, holding the samples meanwhile.

    The rate is 1 / the median spacing of the increasing stamps (the rule ``analyze`` uses,
    :func:`imu_allan.core.checks.preprocess.check_timing`), fixed once the stamps span ``settle_s``
    seconds (or ``max_samples`` have arrived).  The samples that arrive until then are held,
    not lost: :meth:`take` hands them back to be fed with the rate found.
    """

    def __init__(self, settle_s=RATE_SETTLE_S, max_samples=200_000):
        """``settle_s``: stamp span that fixes the rate, s; ``max_samples`` bounds the memory."""
        self.settle_s = float(settle_s)
        self.max_samples = int(max_samples)
        self.rate_hz = None
        self.n_held = 0
        self.n_dropped = 0  # only stamps that never increase, over max_samples of them
        self._t, self._data = [], []
        self._first = self._last = None

    def add(self, t, data):
        """Hold samples (stamps ``t`` in s, ``data`` (n, A)); return the rate (Hz) once fixed."""
        from ..checks.preprocess import check_timing
        t = np.asarray(t, dtype=float)
        if self.rate_hz is not None or t.size == 0:
            return self.rate_hz
        self._t.append(t)
        self._data.append(np.asarray(data, dtype=float))
        self.n_held += t.size
        self._first = float(t[0]) if self._first is None else self._first
        self._last = float(t.max()) if self._last is None else max(self._last, float(t.max()))
        if self._last - self._first >= self.settle_s or self.n_held >= self.max_samples:
            try:
                # exactly the first settle_s seconds (or max_samples): the rate does not
                # depend on how the stream was cut into batches
                t = np.concatenate(self._t)
                if self._last - self._first >= self.settle_s:
                    t = t[t <= self._first + self.settle_s]
                self.rate_hz = check_timing(t[:self.max_samples]).rate_hz
            except ValueError:  # stamps that never increase: keep waiting, bounded
                if self.n_held >= self.max_samples:
                    self._t, self._data = self._t[-1:], self._data[-1:]
                    self.n_dropped += self.n_held - self._t[0].size
                    self.n_held = self._t[0].size
        return self.rate_hz

    def take(self):
        """Return the held samples ``(t, data)`` in arrival order (none are held afterwards)."""
        t, data = np.concatenate(self._t), np.concatenate(self._data)
        self._t, self._data, self.n_held = [], [], 0
        return t, data


def stream_health(monitor, recent, silence_s, timeout_s=2.0, rate_tolerance=0.1,
                  excluded_share=math.nan, max_excluded_share=0.5, name='IMU stream',
                  rejected=None):
    """
    Health of the input stream: stamps, rate and motion-gate exclusions.

    ``recent``: ``monitor.take_recent()`` for the span since the last report; ``silence_s``:
    time since the last message (s, wall or ROS clock; inf if none ever), ERROR above
    ``timeout_s``.  WARN when the measured rate is off the configured one by more than
    ``rate_tolerance`` (10 %, the diagnostic_updater FrequencyStatus default), on stamp gaps
    or out-of-order stamps since the last report, when the gate left out more than
    ``max_excluded_share`` of the decided samples (``excluded_share``, NaN without a gate:
    the estimate is starved) and on ``rejected`` (``{axis: n}`` NaN, inf or non-physical
    samples since the last report, :meth:`OnlineAllan.take_rejected`).
    """
    rate = recent['rate_hz'] if math.isfinite(recent['rate_hz']) else monitor.measured_rate()
    values = {
        'rate_hz': rate, 'expected_rate_hz': monitor.rate_hz,
        'samples_total': monitor.n_kept,
        'gaps_total': monitor.gaps, 'gaps_recent': recent['gaps'],
        'max_gap_s': monitor.max_gap_s,
        'out_of_order_total': monitor.out_of_order,
        'out_of_order_recent': recent['out_of_order'],
        'silence_s': silence_s,
        'excluded_share': excluded_share,
    }
    if monitor.n_kept == 0:
        if math.isfinite(silence_s) and silence_s > timeout_s:
            return Health(name, ERROR, f'no usable samples for {silence_s:.1f} s', values)
        return Health(name, STALE, 'no samples received yet', values)
    if silence_s > timeout_s:
        return Health(name, ERROR, f'no samples for {silence_s:.1f} s', values)
    rejected = rejected or {}
    checks = [
        (math.isfinite(rate) and abs(rate / monitor.rate_hz - 1.0) > rate_tolerance,
         f'rate {rate:.4g} Hz differs from configured {monitor.rate_hz:.4g} Hz'),
        (recent['gaps'], f'{recent["gaps"]} stamp gap(s) (max {monitor.max_gap_s:.3g} s)'),
        (recent['out_of_order'], f'{recent["out_of_order"]} out-of-order stamp(s) dropped'),
        (math.isfinite(excluded_share) and excluded_share > max_excluded_share,
         f'{100 * excluded_share:.0f} % of samples excluded as motion'),
        (rejected, 'samples rejected as NaN, inf or non-physical: '
         + ', '.join(f'{a} {n}' for a, n in rejected.items()))]
    problems = [text for failed, text in checks if failed]
    values.update({f'rejected_recent.{axis}': n for axis, n in rejected.items()})
    return Health(name, WARN if problems else OK, '; '.join(problems) or 'ok', values)


def discrepancy_health(model, result, axes=AXES, prefix=''):
    """
    Model-vs-data check for the allan node's ``model_file``: one :class:`Health` per axis.

    Uses :func:`imu_allan.core.discrepancy.gap_summary` (analytic band, milliseconds per axis):
    OK when the measured curve is consistent with the model, WARN with the gap (about 1 means
    consistent, see docs/discrepancy.md) and the effect that fits the excess otherwise, STALE
    while there is no estimate or the model has no terms for the axis.
    """
    from ..discrepancy import gap_summary
    summary = gap_summary(model, result) if result is not None else {}
    out = []
    for axis in axes:
        name = f'{prefix}{axis} model discrepancy'
        entry = summary.get(axis)
        if entry is None:
            out.append(Health(name, STALE, 'no estimate yet, or no model terms for this axis',
                              {}))
            continue
        band = entry.get('tau_range_s')
        values = {'gap': float(entry['gap']), 'p_value': float(entry['p_value']),
                  'effect': entry['effect'] or 'none',
                  'tau_range_s': f'{band[0]:.4g}-{band[1]:.4g}' if band else '-'}
        if entry['consistent']:
            out.append(Health(name, OK, f'consistent with the model (gap {entry["gap"]:.2f})',
                              values))
        else:
            effect = entry['effect'] or 'an unnamed effect'
            out.append(Health(name, WARN, f'gap {entry["gap"]:.2f}: data leave the model band'
                                          f' ({effect})', values))
    return out
