"""
The recording advisor (core/fit/advisor.py): targets, forecasts, unresolved pairs, health.

Budget: about 20 s in all, most of it the statistical test (one gyro axis at 10 Hz).
"""

import json
import math

from core.advisor_cases import cases, RATE_HZ, rel_halfwidth, SEEDS
from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.fit import fit_noise_model
from imu_allan.core.fit.advisor import (
    _AxisAdvisor,
    _nonlinear,
    Advice,
    advice_health,
    advise,
    analysis_grid,
    DEFAULT_TARGETS,
    HORIZON,
    parse_targets,
    TermAdvice,
    Unresolved,
)
from imu_allan.core.fit.bisection import run
from imu_allan.core.live import health
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.errors import InputError
from imu_allan.report.advice import advice_sentence, advice_to_json
import pytest


def test_parse_targets_merges_over_the_defaults():
    assert parse_targets('') == DEFAULT_TARGETS
    got = parse_targets(' bias_instability=0.05 , white_noise=0.01')
    assert got['bias_instability'] == 0.05 and got['white_noise'] == 0.01
    assert got['rate_random_walk'] == DEFAULT_TARGETS['rate_random_walk']


@pytest.mark.parametrize('text, problem', [
    ('bias=0.1', "unknown term 'bias'"),
    ('white_noise=fast', 'is not a number'),
    ('white_noise=0', 'outside'),
    ('white_noise=2', 'outside'),
    ('white_noise', 'is not TERM=REL'),
])
def test_parse_targets_rejects_bad_input_in_one_line(text, problem):
    with pytest.raises(InputError) as err:
        parse_targets(text, where='targets')
    assert str(err.value).startswith('targets: ') and problem in str(err.value)
    assert '\n' not in str(err.value)


def _record(model, seconds, seed, rate_hz=RATE_HZ, axes=('gyro_x',)):
    data = simulate(NoiseModel(model, rate_hz), int(seconds * rate_hz), rate_hz, seed=seed,
                    axes=list(axes))
    result = allan_deviation(data, rate_hz, axes=list(axes))
    return result, fit_noise_model(result)


def test_forecast_at_the_current_length_reproduces_the_fit():
    """
    A target just under the current half-width needs only a little more data (< 60 %).

    At the current length the forecast equals the fit's own covariance evaluated at its model
    curve, so meeting 0.9 x the current precision of a 1/sqrt(T) term takes about 23 % more:
    if the forecast were off by a factor 1.5 in half-width it would predict 0 or > 100 %.
    """
    model = {'gyro_x': {'white_noise': 5.8e-4, 'rate_random_walk': 5.0e-5}}
    result, fitted = _record(model, 1200.0, seed=4)
    targets = {t: 0.9 * rel_halfwidth(fitted, 'gyro_x', t) for t in model['gyro_x']}
    advice = advise(result, fitted, targets)
    for term in model['gyro_x']:
        more = advice.axes['gyro_x'][term].more_s
        assert 0.05 * 1200.0 < more < 0.6 * 1200.0, (term, more)


def test_met_targets_need_no_more_time():
    result, fitted = _record({'gyro_x': {'white_noise': 5.8e-4}}, 600.0, seed=5)
    advice = advise(result, fitted, {'white_noise': 0.5})
    assert advice.axes['gyro_x']['white_noise'].more_s == 0.0
    assert advice.record_more_s == 0.0


def test_the_prediction_comes_true():
    """
    Achieved half-width within a factor 1.5 of the target for >= 80 % of the cases.

    Cases: white + B, white + K, white + B + K and white + Gauss-Markov, seeds 1 and 2 (the
    table in docs/method.md runs three and includes white noise), each fitted term of the
    model but white noise (the easy 1/sqrt(T) case); the target is half
    the base record's relative half-width and the longer record has a new seed.  Why the
    tolerance is fair: the achieved half-width is itself estimated from one record: it divides
    by the fitted value (which scatters by the target itself, 5-15 %), and the term selection
    of the longer record is random too; a factor 1.5 leaves room for that, while a forecast
    off by more than ~2.3x in time (1.5^2 for a 1/sqrt(T) term) fails the case.
    """
    rows = list(cases(seeds=SEEDS[:2], skip=('white_noise',)))
    assert len(rows) >= 8
    ok = [r for r in rows if r['ok']]
    assert len(ok) >= 0.8 * len(rows), [(r['model'], r['term'], r['ratio']) for r in rows]
    assert all(r['more_s'] > 0 for r in rows)


def test_ten_minutes_of_white_and_b_report_the_unresolved_pair():
    """
    The issue's case: 10 min at 100 Hz, white + B; one gyro axis gets K instead of B.

    Instead of a silent NaN for B, that axis is reported as unresolved (B vs K) with a finite
    time until the two separate, in JSON that has no NaN, and the sentence names it.
    """
    thesis = {'gyro_x': {'white_noise': 5.759587e-04, 'bias_instability': 1.502922e-04},
              'gyro_y': {'white_noise': 5.730498e-04, 'bias_instability': 1.534920e-04},
              'gyro_z': {'white_noise': 6.021386e-04, 'bias_instability': 1.777327e-04}}
    result, fitted = _record(thesis, 600.0, seed=0, rate_hz=100.0, axes=tuple(thesis))
    swapped = [a for a in thesis if 'rate_random_walk' in fitted.model.terms[a]
               and 'bias_instability' not in fitted.model.terms[a]]
    assert swapped, 'seed 0 no longer shows the swap'
    advice = advise(result, fitted)
    for axis in swapped:
        pair = [u for u in advice.unresolved if u.axis == axis
                and set(u.terms) == {'bias_instability', 'rate_random_walk'}]
        assert pair and pair[0].more_s is not None and 0 < pair[0].more_s < 1e5
    doc = advice_to_json(advice)
    json.dumps(doc, allow_nan=False)
    assert doc['record_more_s'] > 0
    sentence = advice_sentence(advice)
    # (the sentence now gives each alternative in words with its own time, issue 22)
    assert f'{swapped[0]}: bias instability or rate random walk: cannot tell yet' in sentence


def test_a_pair_separates_when_the_later_of_its_two_directions_does():
    """
    The pair's time is the later direction's, searched on its own (_pair_time skips work).

    Each direction (one alternative as the truth, fitted with the other) is searched alone
    here, all the way; the pair's time must be the later of the two (None if either has
    none), as it was before the second direction's search was cut short.
    """
    thesis = {'gyro_x': {'white_noise': 5.759587e-04, 'bias_instability': 1.502922e-04},
              'gyro_y': {'white_noise': 5.730498e-04, 'bias_instability': 1.534920e-04}}
    result, fitted = _record(thesis, 600.0, seed=0, rate_hz=100.0, axes=tuple(thesis))
    checked = 0
    for axis in fitted.axes:
        adv = _AxisAdvisor(result, fitted, axis, DEFAULT_TARGETS, analysis_grid())
        n_max = int(adv.n * HORIZON)
        chosen = list(adv.fit.terms)
        run(adv._pairs(adv.fit.terms, n_max))
        _, crit = adv._data_criterion(chosen)
        for u in adv.unresolved:
            alt_fit, alt_crit = adv._data_criterion(list(u.alternative))
            start = _nonlinear(alt_fit.terms)
            times = [run(adv._pair_time([d], alt_crit - crit, start, n_max)) for d in (
                (adv.fit.terms, list(u.alternative), 'fit'),
                (alt_fit.terms, chosen, '+'.join(u.alternative)))]
            assert u.more_s == (None if None in times else adv._more_s(max(times))), (u, times)
            checked += 1
    assert checked >= 2


def _advice(more_b, pair_more=None):
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.003, 0.0),
                             'bias_instability': TermAdvice(0.2, more_b)}
    if pair_more is not False:
        advice.unresolved.append(Unresolved('gyro_x', ('bias_instability', 'rate_random_walk'),
                                            pair_more))
    return advice


def test_advice_health_levels_and_values():
    assert advice_health(None).level == health.STALE
    met = advice_health(_advice(0.0, pair_more=False))
    assert met.level == health.OK and met.values['record_more_s'] == 0.0
    waiting = advice_health(_advice(1800.0, pair_more=5400.0))
    assert waiting.level == health.WARN and '5400 s' in waiting.message
    assert waiting.values['gyro_x.bias_instability.more_s'] == 1800.0
    assert waiting.values['gyro_x.bias_instability_vs_rate_random_walk.more_s'] == 5400.0
    unknown = advice_health(_advice(None, pair_more=False))
    assert unknown.level == health.WARN
    assert math.isnan(unknown.values['gyro_x.bias_instability.more_s'])
