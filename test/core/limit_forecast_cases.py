"""
Does "resolved after about X more if that large" come true?  Cases shared by test_advisor.py.

A 3DM-GX3-25 from the independent generator (startup_cases: its 15-tap window, N and B at the
packaged budget) is fed to the node's pipeline for ``base_s``; for each of gyro_x and accel_x
and each of bias instability and rate random walk that the record does not resolve, the
advisor gives the 95 % upper limit L and the time X until a term that large is resolved.  A
new record of base + X s whose term is L (the other terms as before, a new seed) is fed to the
pipeline, and the case counts as come true when the term is resolved there.  The rule
(:func:`imu_allan.core.fit.advisor._separated`: the noise-free criterion gap one standard
deviation above the margin) aims at about 84 %.

``python test/core/limit_forecast_cases.py [seeds] [base_s]`` prints the shares of
docs/method.md section 4.
"""

import math
import os
import sys

if __package__ in (None, ''):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from core import startup_cases as sc  # noqa: E402
from core.independent_imu import IndependentAxis  # noqa: E402
from imu_allan.core.fit.advisor import advise  # noqa: E402
from imu_allan.core.live.online import OnlineAllan  # noqa: E402
from imu_allan.core.units import AXES  # noqa: E402
import numpy as np  # noqa: E402

CASES = (('gyro_x', 'bias_instability'), ('gyro_x', 'rate_random_walk'),
         ('accel_x', 'bias_instability'), ('accel_x', 'rate_random_walk'))


def _feed(axes, names, seconds):
    pipeline = OnlineAllan(sc.RATE, names, filter_window_s=sc.DEVICE.taps / 1000.0)
    n = int(seconds * sc.RATE)
    pipeline.feed(np.arange(n) / sc.RATE, np.column_stack([a.take(n) for a in axes]))
    result = pipeline.result()
    return pipeline.fit(result), result


def run(seeds, base_s):
    """Return ``[(axis, term, in_open_set, more_s, resolved), ...]`` over ``seeds``."""
    rows = []
    for seed in seeds:
        axes, budget = sc.unit(1.0, np.random.default_rng(900 + seed), base_s)
        fitted, result = _feed(axes, AXES, base_s)
        advice = advise(result, fitted)
        for axis, term in CASES:
            lim = advice.limits.get(axis, {}).get(term)
            if lim is None or lim.more_s is None or lim.upper_limit is None:
                continue
            truth = {'white_noise': budget.limit(axis, 'white_noise')
                     / math.sqrt(sc.DEVICE.fold()),
                     'bias_instability': budget.limit(axis, 'bias_instability'),
                     term: lim.upper_limit}
            total = base_s + lim.more_s
            again = IndependentAxis(truth, sc.RATE, total, np.random.default_rng(5000 + seed),
                                    sc.DEVICE)
            refit, _ = _feed([again], (axis,), total)
            rows.append((axis, term, lim.in_open_set, lim.more_s, term in refit.resolved(axis)))
    return rows


def shares(rows):
    """Return ``{'open': (cases, share resolved), 'absent': ...}``."""
    out = {}
    for name, kind in (('open', True), ('absent', False)):
        hits = [r[4] for r in rows if r[2] == kind]
        if hits:
            out[name] = (len(hits), float(np.mean(hits)))
    return out


if __name__ == '__main__':
    n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    base = float(sys.argv[2]) if len(sys.argv) > 2 else 30.0
    for name, (n, share) in shares(run(range(n_seeds), base)).items():
        print(f'{base:g} s, {name} terms: {n} cases, resolved at the advised time {share:.1%}')
