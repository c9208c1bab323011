#!/usr/bin/env python3
"""
Measure the change test's false-alarm rate on simulated static records (no change at all).

Simulates ``--hours`` of a noise model (default: the thesis 3DM-GX3-25 model, all six axes,
plus a rate random walk unless ``--no-walk``) at ``--rate`` Hz per seed, runs the dynamic
Allan variance and the change test with the default threshold, and prints the false alarms
per axis per day (and a 95 % upper bound when there are none, Poisson: 3 / axis-days).

    python3 scripts/dynamic_false_alarms.py --hours 24 --seeds 1
"""

import argparse
import math
import time

from imu_allan.core.change.detection import detect_changes
from imu_allan.core.change.dynamic import dynamic_allan
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate


def main():
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('--hours', type=float, default=24.0)
    p.add_argument('--rate', type=float, default=100.0)
    p.add_argument('--seeds', type=int, default=1)
    p.add_argument('--first-seed', type=int, default=1000)
    p.add_argument('--window', type=float, default=None, help='window, s (default: the rule)')
    p.add_argument('--no-walk', action='store_true', help='no rate random walk term')
    args = p.parse_args()
    from importlib.resources import files
    model = NoiseModel.from_yaml(str(files('imu_allan') / 'data' / 'gx3_25_thesis.yaml'))
    if not args.no_walk:  # flicker + random walk: the usual static model
        for axis in model.axes:
            k = 2e-6 if axis.startswith('gyro') else 2e-5
            model.terms[axis]['rate_random_walk'] = {'value': k}
    n = int(args.hours * 3600 * args.rate)
    alarms, axis_days = [], 0.0
    for seed in range(args.seeds):
        t0 = time.time()
        data = simulate(model, n, args.rate, seed=args.first_seed + seed)
        dyn = dynamic_allan(data, args.rate, args.window, axes=model.axes)
        del data
        found = detect_changes(dyn)
        alarms += found
        axis_days += len(model.axes) * args.hours / 24.0
        print(f'seed {seed}: window {dyn.window_s:.0f} s, step {dyn.step_s:.0f} s, '
              f'{len(found)} alarm(s) {[c.to_json() for c in found]} ({time.time() - t0:.0f} s)',
              flush=True)
    rate = len(alarms) / axis_days
    bound = (3.0 if not alarms else len(alarms) + 2.0 * math.sqrt(len(alarms)) + 2) / axis_days
    print(f'false alarms: {len(alarms)} in {axis_days:g} axis-days = {rate:.3g} per axis-day '
          f'(95 % upper bound about {bound:.3g}); model {model.axes} at {args.rate:g} Hz')


if __name__ == '__main__':
    main()
