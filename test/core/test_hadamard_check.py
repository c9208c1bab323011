"""The Hadamard check of the term selection (core/fit/hadamard_check.py): mechanics, not power."""

from imu_allan import allan_deviation, fit_noise_model, NoiseModel, simulate
from imu_allan.core.deviations import deviation
from imu_allan.core.fit import hadamard_check, Problem
import numpy as np
import pytest


@pytest.fixture(scope='module')
def record():
    model = NoiseModel.from_dict({'gyro': {'white_noise': 2e-3, 'bias_instability': 2e-3,
                                           'rate_ramp': 3e-5}})
    data = simulate(model, 360_000, 100.0, seed=5, axes=['gyro_x'])
    ohdev = deviation(data, 100.0, 'ohdev', axes=['gyro_x'])
    return allan_deviation(data, 100.0, axes=['gyro_x']), ohdev


def test_without_the_curve_nothing_changes(record):
    result, ohdev = record
    plain = fit_noise_model(result)
    checked = fit_noise_model(result, deviations={'ohdev': ohdev})
    assert plain.fits['gyro_x'].evidence == [] and plain.rejected('gyro_x') == []
    evidence = checked.fits['gyro_x'].evidence
    # evidence only where the open sets differ in K; never every open set rejected
    for entry in evidence:
        assert entry['curve'] == 'ohdev' and entry['walk_max'] >= 0.0
    if evidence:
        assert not all(e['rejected'] for e in evidence)


def test_rejected_sets_leave_the_alternatives(record):
    """A set the curve contradicts is reported under rejected() and not as an alternative."""
    result, _ = record
    fitted = fit_noise_model(result)
    fit = fitted.fits['gyro_x']
    others = [list(names) for crit, names in fit.candidates
              if crit - fit.candidates[0][0] < hadamard_check.ALTERNATIVE_MARGIN
              and set(names) != set(fit.terms)]
    if not others:
        pytest.skip('the Allan fit left no alternative on this record')
    fit.evidence = [{'terms': others[0], 'curve': 'ohdev', 'gain': 12.0, 'rejected': True}]
    assert others[0] not in fitted.alternatives('gyro_x')
    assert fitted.rejected('gyro_x') == [{'terms': others[0], 'by': 'ohdev', 'gain': 12.0}]
    if len(fitted.alternatives('gyro_x')) == 1:
        assert fitted.decided_by('gyro_x') == 'oadev+ohdev'


def test_hadamard_problem_ignores_the_ramp_and_short_cluster_counts(record):
    result, ohdev = record
    problem = hadamard_check.hadamard_problem(
        ohdev, 'gyro_x', {'white_noise': 4e-6, 'bias_instability': 4e-6, 'rate_ramp': 9e-10})
    assert np.all(problem.column('rate_ramp') == 0.0)
    assert problem.tau[-1] * 100.0 * hadamard_check.MIN_CLUSTERS <= ohdev.n_samples
    # flicker-dominated long taus: a flicker EDF (tens), not the white-PM one (1e5)
    assert np.all(problem.edf[problem.tau > 50.0] < 100.0)


NBK = ('white_noise', 'bias_instability', 'rate_random_walk')
NBR = ('white_noise', 'bias_instability', 'rate_ramp')


@pytest.mark.parametrize('seed', [1, 2, 3])
@pytest.mark.parametrize('slow', [{'rate_ramp': 3e-6}, {'rate_random_walk': 3e-5}])
def test_the_check_contradicts_a_walk_where_a_ramp_rises(seed, slow):
    """
    Given both sets open, a true ramp rejects N B K and keeps N B R; a true walk keeps N B K.

    1 h at 100 Hz, N 2e-3, B 2e-4 and a ramp of 3e-6 rad/s^2 or a walk of 3e-5 rad/s^2/sqrt(Hz)
    (each above the white noise over the last half decade of the Allan curve).  Measured on
    seeds 1-3: with the ramp, the lower end of the walk N B K needs is 1.48-2.07x the most the
    Hadamard curve allows (1.9-2.3x before the fit moved to the log domain, whose walk
    interval is wider; the rule rejects at 1x); with the walk, N B K is never rejected (the
    Hadamard curve, half as sensitive to K and cut at T/10, rarely confirms the walk: then it
    rejects nothing, which is what the check must do when it cannot tell).
    """
    model = NoiseModel.from_dict({'gyro': {'white_noise': 2e-3, 'bias_instability': 2e-4,
                                           **slow}})
    data = simulate(model, 360_000, 100.0, seed=seed, axes=['gyro_x'])
    result = allan_deviation(data, 100.0, axes=['gyro_x'])
    allan = Problem(result.tau, result.avar[:, 0], result.edf[:, 0], result.alpha[:, 0], 100.0,
                    3600.0)
    coef = {'white_noise': 4e-6, 'bias_instability': 4e-8, **{k: v * v for k, v in slow.items()}}
    hadamard = hadamard_check.hadamard_problem(
        deviation(data, 100.0, 'ohdev', axes=['gyro_x']), 'gyro_x', coef)
    verdict = {tuple(e['terms']): e for e in
               hadamard_check.check(allan, hadamard, [(0.0, NBK), (1.0, NBR)])}
    if 'rate_ramp' in slow:
        assert verdict[NBK]['rejected'] and not verdict[NBR]['rejected']
        assert verdict[NBK]['walk_min'] > 1.3 * verdict[NBK]['walk_max']
    else:
        assert not verdict[NBK]['rejected']


def test_the_advice_leaves_out_a_contradicted_set():
    """
    A set the fit's evidence rejects is no unresolved pair of the recording advice.

    Seed 3 of the clear ramp record leaves an alternative open (the advisor then reports it
    among the axis's open sets); with that set marked contradicted it is gone.
    """
    from imu_allan.core.fit.advisor import advise
    model = NoiseModel.from_dict({'gyro': {'white_noise': 2e-3, 'bias_instability': 2e-4,
                                           'rate_ramp': 3e-6}})
    data = simulate(model, 360_000, 100.0, seed=3, axes=['gyro_x'])
    result = allan_deviation(data, 100.0, axes=['gyro_x'])
    fitted = fit_noise_model(result)
    others = fitted.alternatives('gyro_x')[1:]
    assert others, 'the record should leave an alternative open'
    before = {frozenset(s) for u in advise(result, fitted).unresolved for s in u.sets}
    assert frozenset(others[0]) in before
    fitted.fits['gyro_x'].evidence = [{'terms': others[0], 'curve': 'ohdev', 'gain': 0.0,
                                       'rejected': True}]
    fitted._weights.clear()  # (the evidence is set after the fit, as decide() would)
    after = {frozenset(s) for u in advise(result, fitted).unresolved for s in u.sets}
    assert frozenset(others[0]) not in after
