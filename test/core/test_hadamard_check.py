"""The Hadamard check of the term selection (core/hadamard_check.py): mechanics, not power."""

from imu_allan import allan_deviation, fit_noise_model, NoiseModel, simulate
from imu_allan.core import hadamard_check
from imu_allan.core.deviations import deviation
import numpy as np
import pytest


@pytest.fixture(scope='module')
def record():
    model = NoiseModel.from_dict({'gyro': {'white_noise': 2e-3, 'bias_instability': 2e-3,
                                           'rate_ramp': 3e-5}})
    data = simulate(model, 360_000, 100.0, seed=5, axes=['gyro_x'])
    return allan_deviation(data, 100.0, axes=['gyro_x']), deviation(data, 100.0, 'ohdev',
                                                                     axes=['gyro_x'])


def test_without_the_curve_nothing_changes(record):
    result, ohdev = record
    plain = fit_noise_model(result)
    checked = fit_noise_model(result, deviations={'ohdev': ohdev})
    assert plain.fits['gyro_x'].evidence == [] and plain.rejected('gyro_x') == []
    evidence = checked.fits['gyro_x'].evidence
    # evidence only where the open sets differ in K, every entry with the best set at 0
    for entry in evidence:
        assert entry['curve'] == 'ohdev' and entry['deviance'] >= 0.0
    if evidence:
        assert min(e['deviance'] for e in evidence) == 0.0


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
    fit.evidence = [{'terms': others[0], 'curve': 'ohdev', 'deviance': 12.0, 'rejected': True}]
    assert others[0] not in fitted.alternatives('gyro_x')
    assert fitted.rejected('gyro_x') == [{'terms': others[0], 'by': 'ohdev', 'deviance': 12.0}]
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
