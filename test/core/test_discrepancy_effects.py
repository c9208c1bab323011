"""
Hidden-effect suite of the discrepancy workflow.

Cases (see ``discrepancy_cases.py`` for the sizes and why each effect is hidden):

* 140 effect cases: 5 effects (quantization, rate random walk, rate ramp, Gauss-Markov, sinusoid)
  on axes 1-5 of six-axis runs, plus white noise and bias instability missing from a one-term
  start on single-axis runs; 10 seeds x 2 sample rates (50 Hz for 30 min, 200 Hz for 10 min);
* 140 no-effect cases: axis 0 of every six-axis effect run plus 20 six-axis runs with nothing
  hidden;
* two effects hidden together on six axes; the thesis scenario (3DM-GX3-25 plus a rate random
  walk, from the thesis's two-term model).

All seeds are fixed, so the counts are reproducible; the tolerances are what the issue asks
(>= 90 % named, >= 95 % clean) and are met with a margin (docs/discrepancy.md lists the
measured rates).
"""

from core.discrepancy_cases import (
    effect_suite,
    EFFECTS,
    make_truth,
    missing_base_suite,
    N_SIMS,
    null_suite,
    records_of,
    run_case,
    SETUPS,
    summarize,
    summary_table,
)
from imu_allan.core.discrepancy import run_discrepancy
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
import pytest


@pytest.fixture(scope='module')
def effect_records():
    """All six-axis effect runs (their axis 0 is a no-effect case) and the single-axis runs."""
    return effect_suite() + missing_base_suite()


@pytest.fixture(scope='module')
def null_records():
    """20 six-axis runs with nothing hidden."""
    return null_suite()


@pytest.mark.slow
def test_names_the_hidden_effect(effect_records):
    stats = summarize(effect_records)
    assert stats['n_effect'] == 140
    assert stats['named_rate'] >= 0.90, summary_table(effect_records)
    # no single effect may be systematically missed: at least 15 of its 20 cases
    for effect, (named, total) in summary_table(effect_records).items():
        if effect != 'none':
            assert total == 20 and named >= 15, (effect, named, total)


def test_parameters_within_their_intervals(effect_records):
    """
    True parameters inside the reported 95 % intervals.

    With honest intervals 95 % of the named cases would cover; 85 % leaves room for the
    approximations (sandwich covariance, log-normal intervals) while still failing for intervals
    that are too narrow by a factor of 1.5 or more (coverage would drop below ~80 %).
    """
    stats = summarize(effect_records)
    assert stats['covered_rate'] >= 0.85


def test_gap_goes_from_inconsistent_to_consistent(effect_records):
    stats = summarize(effect_records)
    assert stats['inconsistent_before'] >= 0.90  # the hidden effect makes the start fail ...
    assert stats['consistent_after'] >= 0.90     # ... and the named effect repairs it
    named = [r for r in effect_records if r['truth'] and r['found'][:1] == r['truth']]
    # the gap shrinks by a factor of two or more in the typical (median) case
    ratios = sorted(r['gap_before'] / r['gap_after'] for r in named)
    assert ratios[len(ratios) // 2] >= 2.0


@pytest.mark.slow
def test_no_effect_adds_nothing(effect_records, null_records):
    nulls = [r for r in effect_records if not r['truth']] + null_records
    stats = summarize(nulls)
    assert stats['n_null'] == 140 == summarize(effect_records)['n_effect']
    assert stats['null_clean_rate'] >= 0.95
    # and the gap of the untouched start model is about 1 (not inflated, not collapsed)
    gaps = sorted(r['gap_after'] for r in nulls)
    assert 0.5 < gaps[len(gaps) // 2] < 1.2


def test_single_axis_runs_name_each_effect():
    """Each of the five effects alone on a single axis (one seed per rate): >= 9 of 10 named."""
    named = []
    for rate, minutes in SETUPS:
        for k, effect in enumerate(EFFECTS):
            truth = make_truth([[effect]], rate, minutes)
            n = int(round(minutes * 60.0 * rate))
            data = simulate(truth, n, rate, seed=300 + k, axes=['gyro_x'])
            result = run_discrepancy(data, rate, axes=['gyro_x'], n_sims=N_SIMS, seed=k)
            named.append((effect, result.effects('gyro_x')))
    assert sum(found[:1] == [effect] for effect, found in named) >= 9, named


PAIRS = (('quantization', 'rate_random_walk'), ('gauss_markov', 'rate_ramp'),
         ('sinusoid', 'rate_random_walk'), ('quantization', 'gauss_markov'),
         ('sinusoid', 'rate_ramp'), ('quantization', 'sinusoid'))


@pytest.mark.parametrize('rate, minutes, seed', [(50.0, 30.0, 71), (200.0, 10.0, 72)])
def test_two_effects_hidden_together(rate, minutes, seed):
    """
    Both effects found on every axis of a six-axis run (either order), gap consistent.

    One miss in six pairs is tolerated per run (a pair's weaker effect can be partly absorbed by
    the first one's refit); the issue's requirement is checked over 12 pairs: >= 10 complete.
    """
    per_axis = [list(p) for p in PAIRS]
    truth, result = run_case(per_axis, rate, minutes, seed)
    complete = sum(set(result.effects(a)) == set(p) for a, p in zip(result.axes, PAIRS))
    assert complete >= 5, [(a, result.effects(a)) for a in result.axes]
    assert sum(result.final_gaps[a].consistent for a in result.axes) >= 5


def test_thesis_scenario():
    """
    3DM-GX3-25 with the thesis's coefficients plus a rate random walk it never looked for.

    One hour at 100 Hz; the RRW crosses the flicker floor near 20 s (gyros; K = 4e-5
    rad/s^2/sqrt(Hz) = 0.5 deg/h/sqrt(h)) and 20-45 s (accelerometers; K = 1.7e-4
    m/s^3/sqrt(Hz)), invisible sample to sample.  Starting from
    the thesis's two-term model the workflow must add a rate random walk on at least 5 of 6
    axes, recover K within its 95 % interval and end consistent.
    """
    thesis = thesis_gx3_25_model()
    model = thesis
    k_true = {}
    for axis in model.axes:
        k = 4e-5 if axis.startswith('gyro') else 1.7e-4
        model = model.with_term(axis, 'rate_random_walk', {'value': k})
        k_true[axis] = k
    rate = 100.0
    data = simulate(model, int(3600 * rate), rate, seed=2024)
    # the thesis's model file as given (its coefficients, no fit): what an engineer would start
    # from after reading the thesis
    result = run_discrepancy(data, rate, axes=model.axes, model=thesis, n_sims=N_SIMS, seed=3)
    hits = covered = 0
    for axis in model.axes:
        steps = [s for s in result.steps if s.axis == axis]
        assert not result.initial_gaps[axis].consistent
        if steps and steps[0].effect == 'rate_random_walk':
            hits += 1
            lo, hi = steps[0].parameters['value']['ci95']
            covered += lo <= k_true[axis] <= hi
        assert result.final_gaps[axis].consistent, (axis, result.effects(axis))
    assert hits >= 5 and covered >= hits - 1
    records = records_of(model, result, [['rate_random_walk']] * 6)
    assert summarize(records)['named_rate'] >= 5 / 6
