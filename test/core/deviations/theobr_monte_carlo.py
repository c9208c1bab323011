"""
Monte Carlo behind docs/method.md section 8: Theo1 on automatic (ThêoBR) vs per-tau noise ID.

Not collected by pytest (minutes).  Run from the worktree with the installed package on the
path: ``python test/core/deviations/theobr_monte_carlo.py N RECORDS`` (the table used 1000 400
and 10000 100).  The generators are written here, independently of the package's simulator:
first differences of white noise (white PM), white noise (white FM), its cumulative sum
(random-walk FM) and white noise plus 0.02 x a random walk (an IMU's white noise below its
random walk).  Truth: OADEV at tau = 0.75 m tau0 averaged over 8 records 20x longer.
Printed: median and 10-90 % range of (printed Theo1) / (true deviation) at four factors for
the per-tau ACF/B1 identification with Howe & Tasset's bias (the package before), ThêoBR (now)
and the true alpha fixed; and how often ThêoBR's k names the noise.
"""

import sys

from imu_allan.core.allan.estimate import _phase
from imu_allan.core.deviations import allan_family, api, noise_id, theo, total_kernel
import numpy as np


def main(n, records, seed=11):
    rng = np.random.default_rng(seed)
    gens = {
        'white PM': (2, lambda k: np.diff(rng.standard_normal((k + 1, records)), axis=0)),
        'white FM': (0, lambda k: rng.standard_normal((k, records))),
        'RW FM': (-2, lambda k: np.cumsum(rng.standard_normal((k, records)), axis=0)),
        'white + RW FM': (None, lambda k: rng.standard_normal((k, records))
                          + 0.02 * np.cumsum(rng.standard_normal((k, records)), axis=0)),
    }
    ms = np.unique(np.array([10, 100 if n <= 1000 else n // 100, n // 2, n - 1]) // 2 * 2)
    print(f'N = {n} samples, {records} records, m = {list(ms)}')
    for name, (alpha, make) in gens.items():
        truth = np.mean(allan_family.variance_reference(
            'oadev', _phase(make(20 * n)[:, :8]), np.round(0.75 * ms).astype(int)), axis=1)
        y = make(n)
        x = _phase(y)
        raw = total_kernel.variance('theo1', x, ms, [1] * len(ms))
        ids = noise_id.identify_phase(x, np.maximum(np.round(0.75 * ms), 1).astype(int), 2,
                                      (-2, 2))
        per_tau = raw * np.array([[theo.bias(a, m) for a in row] for m, row in zip(ms, ids)])
        run_alpha, factor = api.run_bias('theo1', x, y)
        ways = {'per-tau ID': per_tau, 'ThêoBR': raw / factor[None, :]}
        if alpha is not None:
            ways['true alpha'] = raw * np.array([[theo.bias(alpha, m)] for m in ms])
        share = ', '.join(f'{a}: {np.mean(run_alpha == a):.0%}' for a in (2, 1, 0, -1, -2)
                          if np.any(run_alpha == a))
        print(f'{name}: k names alpha {share}')
        for way, var in ways.items():
            ratio = np.sqrt(var / truth[:, None])
            cells = [f'm={m}: {np.median(r):.2f} [{np.percentile(r, 10):.2f}, '
                     f'{np.percentile(r, 90):.2f}]' for m, r in zip(ms, ratio)]
            print(f'  {way:11s}', '  '.join(cells))


if __name__ == '__main__':
    main(int(sys.argv[1]), int(sys.argv[2]))
