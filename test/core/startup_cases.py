"""
The allan node's budget check from start-up, measured: false alarms and time to a true one.

A 3DM-GX3-25 as the independent generator makes it (independent_imu.py: white noise through
the device's 15-tap window at 1 kHz decimated to 100 Hz, flicker), its N and B at ``ratio``
times the packaged datasheet budget (imu_allan/data/gx3_25_budget.yaml), is fed to the node's
pipeline (:class:`imu_allan.core.live.online.OnlineAllan`) in blocks of the node's publish
period (10 s), and every publication is checked against the budget as the node checks it
(:func:`imu_allan.core.live.health.budget_health` on the coefficient table and its limit
block, :mod:`imu_allan.report.coeffs_layout`).  Per start-up: the publications with an ERROR
or a WARN, per term; for a unit over budget, the first publication that flags the term and
the first from which it stays flagged.

``python test/core/startup_cases.py [start-ups] [--seconds S] [--ratio R]`` prints the
figures of docs/online.md; test_startup.py runs a fast part.
"""

from concurrent.futures import ProcessPoolExecutor
import math
import os
import sys
import time

if __package__ in (None, ''):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from core.independent_imu import Device, IndependentAxis  # noqa: E402
from imu_allan.core.live import health as hm  # noqa: E402
from imu_allan.core.live.online import OnlineAllan  # noqa: E402
from imu_allan.core.units import AXES, is_gyro  # noqa: E402
from imu_allan.report import coeffs_layout as layout  # noqa: E402
import numpy as np  # noqa: E402

RATE = 100.0
PUBLISH_S = 10.0
BUDGETED = ('white_noise', 'bias_instability')
#: The device's window: 15 taps at 1 kHz, every tenth average kept (the factory setting).
DEVICE = Device(decimation=10, taps=15)


def unit(ratio, rng, seconds):
    """Six axes of a GX3-25 whose white-noise density and B are ``ratio`` x the budget."""
    budget = hm.NoiseBudget.from_yaml()
    axes = []
    for axis in AXES:
        n_out = ratio * budget.limit(axis, 'white_noise')
        # the output's density is the input's times sqrt(fold): the budget binds the output
        n_in = n_out / math.sqrt(DEVICE.fold())
        truth = {'white_noise': n_in, 'bias_instability': ratio * budget.limit(
            axis, 'bias_instability')}
        axes.append(IndependentAxis(truth, RATE, seconds, rng, DEVICE))
    return axes, budget


def startup(args):
    """One start-up of ``seconds``: per publication the budget levels per (axis, term)."""
    ratio, seconds, seed = args
    rng = np.random.default_rng(seed)
    axes, budget = unit(ratio, rng, seconds)
    pipeline = OnlineAllan(RATE, AXES, filter_window_s=DEVICE.taps / 1000.0)
    block = int(PUBLISH_S * RATE)
    out = []
    for k in range(int(seconds / PUBLISH_S)):
        data = np.column_stack([a.take(block) for a in axes])
        pipeline.feed((k * block + np.arange(block)) / RATE, data)
        fitted = pipeline.fit(pipeline.result())
        if fitted is None:
            continue
        table = layout.coefficient_table(fitted, AXES)
        limits = layout.limit_values(fitted, AXES).reshape(len(AXES), -1)
        levels = {}
        for axis, rec in zip(AXES, hm.budget_health(table, budget, AXES, limits=limits,
                                                    alarm_lows=layout.alarm_lows(fitted, AXES))):
            for term in BUDGETED:
                levels[(axis, term)] = budget.level(axis, term, rec.values[term],
                                                    rec.values.get(f'{term}.alarm_low', math.nan))
        out.append(((k + 1) * PUBLISH_S, levels))
    return out


def run(n, ratio, seconds, seed=100, workers=None):
    """Return the publications of ``n`` start-ups: ``[[(t_s, {(axis, term): level})...]...]``."""
    jobs = [(ratio, seconds, seed + k) for k in range(n)]
    workers = workers or min(2, os.cpu_count() or 1)
    if workers == 1:
        return [startup(job) for job in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(startup, jobs))


def summary(runs):
    """Return ERROR / WARN publication counts per term and the share of WARN publications."""
    out = {}
    for term in BUDGETED:
        levels = [lv for pubs in runs for _, lv in pubs for (a, t), lv in lv.items() if t == term]
        out[term] = {'publications': len(levels),
                     'error': sum(v == hm.ERROR for v in levels),
                     'warn': sum(v >= hm.WARN for v in levels),
                     'startups_with_error': sum(any(lv[k] == hm.ERROR for _, lv in pubs
                                                    for k in lv if k[1] == term)
                                                for pubs in runs)}
        out[term]['warn_share'] = out[term]['warn'] / max(len(levels), 1)
    return out


def time_to_flag(runs, term, kind):
    """Per start-up and ``kind`` axis (gyro / accel): first flagged time, time flagged for good."""
    first, stays = [], []
    for pubs in runs:
        for axis in AXES:
            if is_gyro(axis) != (kind == 'gyro'):
                continue
            flags = [(t, lv[(axis, term)] >= hm.WARN) for t, lv in pubs]
            hit = [t for t, f in flags if f]
            first.append(hit[0] if hit else math.inf)
            stay = math.inf
            for t, f in reversed(flags):
                if not f:
                    break
                stay = t
            stays.append(stay)
    return np.array(first), np.array(stays)


if __name__ == '__main__':
    args = [a for a in sys.argv[1:] if not a.startswith('--')]
    count = int(args[0]) if args else 200
    seconds = float(sys.argv[sys.argv.index('--seconds') + 1]) if '--seconds' in sys.argv \
        else 600.0
    ratio = float(sys.argv[sys.argv.index('--ratio') + 1]) if '--ratio' in sys.argv else 1.0
    t0 = time.time()
    runs = run(count, ratio, seconds)
    print(f'{count} start-ups of {seconds:g} s at {ratio:g} x budget')
    for term, s in summary(runs).items():
        print(f'  {term}: {s["publications"]} axis-publications, ERROR {s["error"]} '
              f'({s["startups_with_error"]} start-ups), WARN {s["warn"]} '
              f'({100 * s["warn_share"]:.2f} %)')
    if ratio > 1:
        for term in BUDGETED:
            for kind in ('gyro', 'accel'):
                first, stays = time_to_flag(runs, term, kind)
                print(f'  {term} {kind}: first flagged median {np.median(first):.0f} s '
                      f'[{np.percentile(first, 10):.0f}, {np.percentile(first, 90):.0f}], '
                      f'flagged for good from median {np.median(stays):.0f} s '
                      f'[{np.percentile(stays, 10):.0f}, {np.percentile(stays, 90):.0f}]')
    print(f'{time.time() - t0:.0f} s', file=sys.stderr)
