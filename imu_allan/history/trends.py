"""
Per-IMU trends of white noise N and bias instability B from the history, and their flags.

ROS-free; reads the ``measurements`` table (:mod:`imu_allan.history.db`).  Only static records
count (a moving IMU's Allan deviation measures the motion) and only detected values make a
trend (upper limits are kept for the plots).

Two flags, each on an IMU's latest record:

* **history** (per axis): the latest value's 68.3 % interval lies wholly outside the band
  ``median +- K_SPREAD * spread`` of the IMU's earlier values, where ``spread`` is the larger of
  their robust standard deviation (1.4826 MAD) and their typical interval half-width.  Median
  and MAD, not mean and range, so that a rise sustained over the last few records (already in
  the history) does not hide itself.  Needs :data:`MIN_HISTORY` earlier values.
* **fleet** (worst axis of each sensor): the latest value lies above the 95th percentile of
  every other record of the fleet (all IMUs, the same sensor and term) by more than its own
  uncertainty: the larger of its interval's lower half and ``K_SPREAD`` times the spread of the
  IMU's earlier values, the same test as the history flag (a short record's interval
  under-states how much B scatters from record to record; the history shows it).  Needs
  :data:`MIN_FLEET` other records.
"""

from dataclasses import dataclass, field
from datetime import datetime
import math

import numpy as np

from ..core.units import AXES, conventional, sensor_of, TERMS

#: The terms followed, with their letters (the registry's symbols).
TREND_TERMS = {t: TERMS[t].symbol for t in ('white_noise', 'bias_instability')}
SENSORS = ('gyro', 'accel')
WORST = 'worst'
#: Band half-width in spreads; with the interval's own ~1 sigma that is ~4 sigma: a healthy IMU
#: crosses it about once in 10^4 records.
K_SPREAD = 3.0
MIN_HISTORY = 3
FLEET_PERCENTILE = 95.0
MIN_FLEET = 20


@dataclass
class Series:
    """
    One quantity of one IMU over time (SI, continuous-time).

    ``start`` naive UTC datetimes; ``value``, ``low``, ``high`` arrays (detected values and
    their 68.3 % intervals); ``axes`` which axis each point is (the worst axis varies);
    ``limit_start``/``limit`` the 95 % upper limits of records where the term was not detected.
    """

    sensor: str
    term: str
    axis: str
    unit: str
    start: list = field(default_factory=list)
    value: list = field(default_factory=list)
    low: list = field(default_factory=list)
    high: list = field(default_factory=list)
    inputs: list = field(default_factory=list)
    axes: list = field(default_factory=list)
    limit_start: list = field(default_factory=list)
    limit: list = field(default_factory=list)


@dataclass
class Imu:
    """Everything the fleet report shows about one ``imu_id``."""

    imu_id: str
    records: list  # (start_utc, input) of its static records, oldest first
    series: dict  # (sensor, term, axis or WORST) -> Series
    flags: list = field(default_factory=list)


QUERY = """
SELECT m.imu_id, m.input, m.start_utc, m.axis, m.term, m.value, m.ci_low, m.ci_high, m.unit,
       m.detected, m.static
FROM measurements m JOIN inputs i ON i.input = m.input AND i.status = 'ok'
WHERE m.param = 'value' AND m.term IN ('white_noise', 'bias_instability')
  AND m.start_utc IS NOT NULL AND m.value IS NOT NULL AND m.start_utc >= ?
ORDER BY m.imu_id, m.start_utc, m.input, m.axis
"""


def load(con, since=None):
    """Read the history; return ``(imus by id, number of non-static records left out)``."""
    rows = con.execute(QUERY, [since or datetime(1, 1, 1)]).fetchall()
    records, moving = {}, set()
    for imu_id, inp, start, axis, term, value, lo, hi, unit, detected, static in rows:
        if not static:
            moving.add((imu_id, inp))
            continue
        rec = records.setdefault(imu_id, {}).setdefault((start, inp), {})
        rec[(axis, term)] = (value, _nan(lo), _nan(hi), bool(detected), unit)
    imus = {imu_id: _build(imu_id, recs) for imu_id, recs in records.items()}
    return imus, len(moving)


def _nan(x):
    return math.nan if x is None else float(x)


def _build(imu_id, recs):
    order = sorted(recs)
    series = {}
    for sensor in SENSORS:
        axes = [a for a in AXES if sensor_of(a) == sensor]
        for term in TREND_TERMS:
            for axis in axes + [WORST]:
                series[(sensor, term, axis)] = Series(sensor, term, axis, '')
            for key in order:
                vals = recs[key]
                best = None
                for axis in axes:
                    if (axis, term) not in vals:
                        continue
                    value, lo, hi, detected, unit = vals[(axis, term)]
                    s = series[(sensor, term, axis)]
                    s.unit = unit
                    _add(s, key, axis, value, lo, hi, detected)
                    if detected and (best is None or value > best[1]):
                        best = (axis, value, lo, hi, unit)
                if best is not None:
                    s = series[(sensor, term, WORST)]
                    s.unit = best[4]
                    _add(s, key, best[0], *best[1:4], True)
    return Imu(imu_id, order, {k: s for k, s in series.items() if s.value or s.limit})


def _add(s, key, axis, value, lo, hi, detected):
    if not detected:
        s.limit_start.append(key[0])
        s.limit.append(value)
        return
    s.start.append(key[0])
    s.inputs.append(key[1])
    s.axes.append(axis)
    s.value.append(value)
    s.low.append(value if math.isnan(lo) else lo)
    s.high.append(value if math.isnan(hi) else hi)


def history_band(values, lows, highs):
    """``(median, spread)`` of earlier values; spread = max(1.4826 MAD, median half-width)."""
    values = np.asarray(values, dtype=float)
    center = float(np.median(values))
    mad = 1.4826 * float(np.median(np.abs(values - center)))
    half = float(np.median((np.asarray(highs) - np.asarray(lows)) / 2.0))
    return center, max(mad, half)


def _latest(imu, s):
    """Index of the series' point from the IMU's latest record, or None."""
    if s.value and (s.start[-1], s.inputs[-1]) == imu.records[-1]:
        return len(s.value) - 1
    return None


def _describe(s, i):
    conv, conv_unit = conventional(s.axes[i], s.term, s.value[i])
    return (f'{s.value[i]:.3e} {s.unit} [{s.low[i]:.3e}, {s.high[i]:.3e}] '
            f'({conv:.3g} {conv_unit}) on {s.start[i]:%Y-%m-%d %H:%M}')


def _name(s, i):
    where = f'worst axis {s.axes[i]}' if s.axis == WORST else s.axes[i]
    return f'{s.sensor} {s.term} ({TREND_TERMS[s.term]}) {where}'


def _flag(imu, s, i, kind, reference, why):
    return {'imu_id': imu.imu_id, 'kind': kind, 'sensor': s.sensor, 'term': s.term,
            'axis': s.axes[i], 'worst_axis': s.axis == WORST, 'value': s.value[i],
            'ci': [s.low[i], s.high[i]], 'unit': s.unit, 'start_utc': s.start[i].isoformat(),
            'input': s.inputs[i], 'reference': reference,
            'why': f'{imu.imu_id}: {_name(s, i)} latest {_describe(s, i)} {why}'}


def history_flags(imu):
    """Return flags of one IMU whose latest per-axis value left its own history."""
    flags = []
    for (_sensor, _term, axis), s in imu.series.items():
        i = _latest(imu, s)
        if axis == WORST or i is None or i < MIN_HISTORY:
            continue
        center, spread = history_band(s.value[:i], s.low[:i], s.high[:i])
        lo_band, hi_band = center - K_SPREAD * spread, center + K_SPREAD * spread
        if s.low[i] > hi_band:
            direction = 'rose above'
        elif s.high[i] < lo_band:
            direction = 'fell below'
        else:
            continue
        change = 100.0 * (s.value[i] / center - 1.0)
        flags.append(_flag(imu, s, i, 'history', {'median': center, 'spread': spread,
                                                  'band': [lo_band, hi_band], 'records': i},
                           f'{direction} its own history ({change:+.0f} % from the median '
                           f'{center:.3e} of {i} earlier records; interval outside median '
                           f'+- {K_SPREAD:g} x spread {spread:.2e})'))
    return flags


def fleet_flags(imus):
    """Return flags of IMUs whose latest worst-axis value is above the fleet's 95th percentile."""
    flags = []
    for sensor in SENSORS:
        for term in TREND_TERMS:
            key = (sensor, term, WORST)
            points = [(imu_id, k, v) for imu_id, imu in imus.items() if key in imu.series
                      for k, v in enumerate(imu.series[key].value)]
            for imu_id, imu in imus.items():
                s = imu.series.get(key)
                i = _latest(imu, s) if s else None
                if i is None:
                    continue
                others = [v for other, k, v in points if (other, k) != (imu_id, i)]
                if len(others) < MIN_FLEET:
                    continue
                p95 = float(np.percentile(others, FLEET_PERCENTILE))
                margin = s.value[i] - s.low[i]
                if i >= MIN_HISTORY:
                    spread = history_band(s.value[:i], s.low[:i], s.high[:i])[1]
                    margin = max(margin, K_SPREAD * spread)
                if s.value[i] - margin > p95:
                    flags.append(_flag(imu, s, i, 'fleet', {'p95': p95, 'records': len(others),
                                                            'margin': margin},
                                       f"is above the fleet's 95th percentile {p95:.3e} of "
                                       f'{len(others)} other records by more than its '
                                       f'uncertainty {margin:.2e}'))
    return flags


def analyse_fleet(imus):
    """Attach every flag to its IMU; return the list of all flags (IMU by IMU)."""
    fleet = fleet_flags(imus)
    out = []
    for imu_id in sorted(imus):
        imu = imus[imu_id]
        imu.flags = history_flags(imu) + [f for f in fleet if f['imu_id'] == imu_id]
        out.extend(imu.flags)
    return out
