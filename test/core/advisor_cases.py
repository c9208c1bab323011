"""
Does the recording advisor's prediction come true?  Cases shared by test_advisor.py.

For several simulated noise models (one gyro axis at 10 Hz, 20-30 min base records) and seeds:
analyse the base record, ask the advisor how much longer to record until each fitted term of
the model reaches a target (half the relative 68.3 % half-width the base record gives, so the
prediction is about 4x the base length for a 1/sqrt(T) term), then simulate a record of base +
more_s with a new seed, analyse it and compare the half-width it reaches with the target.

``python test/core/advisor_cases.py`` prints the Markdown table of docs/method.md.
"""

import math
import sys
import time

from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.fit import fit_noise_model
from imu_allan.core.fit.advisor import advise
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate

RATE_HZ = 10.0
#: name, terms (one gyro axis, SI), fitted terms (None: automatic), base record s
MODELS = (
    ('white + B', {'white_noise': 5.8e-4, 'bias_instability': 1.5e-4}, None, 1200.0),
    ('white + K', {'white_noise': 5.8e-4, 'rate_random_walk': 5.0e-5}, None, 1200.0),
    ('white + B + K', {'white_noise': 2.0e-4, 'bias_instability': 1.0e-4,
                       'rate_random_walk': 2.0e-5}, None, 1800.0),
    ('white + Gauss-Markov', {'white_noise': 5.8e-4,
                              'gauss_markov': {'sigma': 3.0e-4, 'tau_c': 20.0}},
     ['white_noise', 'gauss_markov'], 1200.0),
)
SEEDS = (1, 2, 3)
#: The target is this fraction of the base record's relative half-width.
TARGET_FRACTION = 0.5
TOLERANCE = 1.5


def rel_halfwidth(fitted, axis, term, selective=True):
    """
    Relative 68.3 % half-width of a term's main parameter (NaN if not fitted).

    ``selective=False``: without the post-selection part of the width, which a term reported
    near its threshold carries now and a longer record, where it stands clear, does not (the
    targets are set from this: half of a width the selection doubled is no target a longer
    record is for).
    """
    params = fitted.model.terms.get(axis, {}).get(term)
    if not params:
        return math.nan
    main = 'sigma' if term == 'gauss_markov' else 'value'
    lo, hi = (fitted.interval(axis, term, main) if selective or term == 'gauss_markov' else
              fitted.averaged_interval(axis, term, selective=False))
    return (hi - lo) / (2.0 * params[main])


def analyse(model, n, seed, terms):
    """Simulate one axis and fit it: ``(AllanResult, FittedModel)``."""
    data = simulate(model, n, RATE_HZ, seed=seed, axes=['gyro_x'])
    result = allan_deviation(data, RATE_HZ, axes=['gyro_x'])
    return result, fit_noise_model(result, terms=terms)


def cases(models=MODELS, seeds=SEEDS, skip=()):
    """
    Yield one row per (model, seed, term): predicted time and achieved half-width.

    Terms in ``skip`` are left out (the test leaves out white noise: its 1/sqrt(T) forecast
    is the easy case, and every case costs a long record).
    """
    for name, axis_terms, terms, base_s in models:
        model = NoiseModel({'gyro_x': axis_terms}, RATE_HZ)
        n0 = int(base_s * RATE_HZ)
        for seed in seeds:
            result, fitted = analyse(model, n0, seed, terms)
            fitted_terms = [t for t in fitted.model.terms.get('gyro_x', {})
                            if t in axis_terms and t not in skip]
            targets = {t: TARGET_FRACTION * rel_halfwidth(fitted, 'gyro_x', t, False)
                       for t in fitted_terms}
            advice = advise(result, fitted, targets, undetected=False)
            for term in fitted_terms:
                entry = advice.axes['gyro_x'][term]
                row = {'model': name, 'seed': seed, 'term': term, 'base_s': base_s,
                       'now': entry.rel_halfwidth, 'target': targets[term],
                       'more_s': entry.more_s, 'achieved': math.nan}
                if entry.more_s is not None:
                    n1 = n0 + int(round(entry.more_s * RATE_HZ))
                    _, longer = analyse(model, n1, 1000 + seed, terms)
                    row['achieved'] = rel_halfwidth(longer, 'gyro_x', term)
                row['ratio'] = row['achieved'] / row['target']
                row['ok'] = 1.0 / TOLERANCE <= row['ratio'] <= TOLERANCE
                yield row


def main():
    """Print the table and the share of cases within the tolerance."""
    start = time.perf_counter()
    rows = list(cases())
    print('| model | seed | term | base s | rel. half-width now | target | predicted more_s '
          '| achieved | achieved / target |')
    print('|---|---|---|---|---|---|---|---|---|')
    for r in rows:
        more = '-' if r['more_s'] is None else f'{r["more_s"]:.0f}'
        print(f'| {r["model"]} | {r["seed"]} | {r["term"]} | {r["base_s"]:.0f} | '
              f'{r["now"]:.3f} | {r["target"]:.3f} | {more} | {r["achieved"]:.3f} | '
              f'{r["ratio"]:.2f}{"" if r["ok"] else " (outside)"} |')
    ok = sum(r['ok'] for r in rows)
    print(f'\n{ok} of {len(rows)} cases within a factor {TOLERANCE} '
          f'({time.perf_counter() - start:.1f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
