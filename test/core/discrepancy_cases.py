"""
Hidden-effect cases for the discrepancy workflow tests (shared by the test modules).

Every case is white noise N = 1e-3 plus bias instability B = 3e-4 (units of the axis) plus at
most one hidden effect sized so that it is below the white-noise level sample to sample (its
per-sample std or step is a fraction of N sqrt(fs)) yet lifts or bends the Allan deviation over
part of the measured span.  Sizes scale with the rate and length so that every effect shows over
a comparable share of the curve:

* quantization: 3 Q^2 / (N^2 dt) = 0.3 at tau0 (AVAR excess of 30 % at the shortest tau);
* rate random walk: crosses the flicker floor at tau_max / 60;
* rate ramp: crosses the flicker floor at tau_max / 8;
* Gauss-Markov: sigma = 2e-3, tau_c = 0.5 s (hump at 0.95 s);
* sinusoid: amplitude 1.5e-3, 0.5 Hz (bump at 0.74 s, nulls at 2, 4, ... s).
"""

import math

from imu_allan.core.discrepancy import run_discrepancy
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.units import AXES
import numpy as np

N_WHITE = 1e-3
B_FLICKER = 3e-4
FLOOR = 0.664282 * B_FLICKER
BASE = {'white_noise': {'value': N_WHITE}, 'bias_instability': {'value': B_FLICKER}}
#: (rate_hz, minutes): the two sample rates of the suite.
SETUPS = ((50.0, 30.0), (200.0, 10.0))
EFFECTS = ('quantization', 'rate_random_walk', 'rate_ramp', 'gauss_markov', 'sinusoid')
N_SIMS = 1  # simulated runs per band: the analytic EDF spread carries most of the weight


def tau_max(rate_hz, minutes):
    """Longest averaging time of the default grid (T / 10), s."""
    return minutes * 60.0 / 10.0


def effect_params(effect, rate_hz, minutes):
    """Parameters of a hidden effect for a setup (see the module docstring)."""
    dt = 1.0 / rate_hz
    tmax = tau_max(rate_hz, minutes)
    if effect == 'quantization':
        return {'value': N_WHITE * math.sqrt(0.1 * dt)}
    if effect == 'rate_random_walk':
        return {'value': FLOOR / math.sqrt(tmax / 60.0 / 3.0)}
    if effect == 'rate_ramp':
        return {'value': FLOOR * math.sqrt(2.0) / (tmax / 8.0)}
    if effect == 'gauss_markov':
        return {'sigma': 2e-3, 'tau_c': 0.5}
    if effect == 'sinusoid':
        return {'amplitude': 1.5e-3, 'frequency_hz': 0.5}
    raise ValueError(effect)


def make_truth(per_axis, rate_hz, minutes):
    """Model with BASE on every axis plus ``per_axis[i]`` (list of effect names) on axis i."""
    terms = {}
    for axis, effects in zip(AXES, per_axis):
        terms[axis] = dict(BASE)
        for effect in effects:
            terms[axis][effect] = effect_params(effect, rate_hz, minutes)
    return NoiseModel(terms, rate_hz)


def run_case(per_axis, rate_hz, minutes, seed, **kwargs):
    """Simulate a case and run the workflow from the two-term start; returns (truth, result)."""
    truth = make_truth(per_axis, rate_hz, minutes)
    n = int(round(minutes * 60.0 * rate_hz))
    axes = truth.axes
    data = simulate(truth, n, rate_hz, seed=seed, axes=axes)
    kwargs.setdefault('n_sims', N_SIMS)
    result = run_discrepancy(data, rate_hz, axes=axes, seed=seed + 1000, **kwargs)
    return truth, result


def covered(step, truth_params, level='ci95'):
    """Return True when every true parameter of the step's effect lies inside its interval."""
    for name, value in truth_params.items():
        entry = step.parameters.get(name)
        if entry is None:
            return False
        lo, hi = entry[level]
        if not lo <= value <= hi:
            return False
    return True


def summarize(records):
    """Rates over a list of per-axis records (dicts with keys set by the suite)."""
    effect = [r for r in records if r['truth']]
    null = [r for r in records if not r['truth']]
    out = {'n_effect': len(effect), 'n_null': len(null)}
    if effect:
        named = [r for r in effect if r['found'][:1] == r['truth']]
        out['named_rate'] = len(named) / len(effect)
        out['covered_rate'] = (sum(r['covered'] for r in named) / len(named)) if named else 0.0
        out['inconsistent_before'] = sum(not r['consistent_before'] for r in effect) / len(effect)
        out['consistent_after'] = (sum(r['consistent_after'] for r in named) / len(named)
                                   if named else 0.0)
    if null:
        out['null_clean_rate'] = sum(not r['found'] for r in null) / len(null)
    return out


def records_of(truth, result, expected):
    """Per-axis records: expected effect list vs what the workflow added."""
    out = []
    for axis, want in zip(result.axes, expected):
        steps = [s for s in result.steps if s.axis == axis]
        found = [s.effect for s in steps]
        cov = False
        if want and found[:1] == want[:1]:
            cov = covered(steps[0], truth.terms[axis][want[0]])
        out.append({'axis': axis, 'truth': list(want), 'found': found, 'covered': cov,
                    'consistent_before': result.initial_gaps[axis].consistent,
                    'consistent_after': result.final_gaps[axis].consistent,
                    'gap_before': result.initial_gaps[axis].value,
                    'gap_after': result.final_gaps[axis].value})
    return out


def effect_suite(seeds=range(10)):
    """Six-axis runs: axis 0 clean, axes 1-5 one hidden effect each; both rates."""
    records = []
    per_axis = [[]] + [[e] for e in EFFECTS]
    for rate, minutes in SETUPS:
        for seed in seeds:
            truth, result = run_case(per_axis, rate, minutes, seed)
            records += records_of(truth, result, per_axis)
    return records


def null_suite(seeds=range(10)):
    """Six-axis runs with no hidden effect; both rates."""
    records = []
    per_axis = [[] for _ in AXES]
    for rate, minutes in SETUPS:
        for seed in seeds:
            truth, result = run_case(per_axis, rate, minutes, 500 + seed)
            records += records_of(truth, result, per_axis)
    return records


def missing_base_suite(seeds=range(10)):
    """
    Single-axis runs where the start lacks white noise or bias instability.

    Twice the length of the six-axis runs (one axis is cheap): the flicker floor then spans a
    decade of averaging times instead of the last few points.
    """
    records = []
    for rate, minutes in SETUPS:
        minutes = 2.0 * minutes
        for seed in seeds:
            for start, missing in ((['bias_instability'], 'white_noise'),
                                   (['white_noise'], 'bias_instability')):
                truth = NoiseModel({'gyro_x': dict(BASE)}, rate)
                n = int(round(minutes * 60.0 * rate))
                data = simulate(truth, n, rate, seed=900 + seed, axes=['gyro_x'])
                result = run_discrepancy(data, rate, axes=['gyro_x'], terms=start,
                                         n_sims=N_SIMS, seed=seed)
                records += records_of(truth, result, [[missing]])
    return records


def summary_table(records):
    """Per-effect naming counts: {effect: (named, total)}."""
    table = {}
    for r in records:
        key = r['truth'][0] if r['truth'] else 'none'
        ok = r['found'][:1] == r['truth'][:1] if r['truth'] else not r['found']
        named, total = table.get(key, (0, 0))
        table[key] = (named + int(ok), total + 1)
    return table


if __name__ == '__main__':  # a quick report for the docs: python test/core/discrepancy_cases.py
    import time
    start = time.time()
    recs = effect_suite() + missing_base_suite()
    nulls = null_suite()
    print('effects', summarize(recs))
    print('null', summarize(nulls))
    print('per effect', summary_table(recs + nulls))
    for r in recs:
        if r['found'][:1] != r['truth'][:1] or not r['covered']:
            print('  miss/cover', r)
    for r in nulls:
        if r['found']:
            print('  false', r)
    print(f'{time.time() - start:.1f} s')
    print(np.round([r['gap_after'] for r in nulls], 2))
