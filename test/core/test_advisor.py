"""
The recording advisor (core/fit/advisor.py): targets, forecasts, open term sets, limits.

Budget: about 20 s in all, most of it the statistical test (one gyro axis at 10 Hz).
"""

import json

from core.advisor_cases import cases, RATE_HZ, rel_halfwidth, SEEDS
from imu_allan.core.allan.estimate import allan_deviation
from imu_allan.core.fit import fit_noise_model, fit_terms
from imu_allan.core.fit.advisor import (
    _AxisAdvisor,
    _nonlinear,
    advise,
    analysis_grid,
    DEFAULT_TARGETS,
    HORIZON,
    parse_targets,
)
from imu_allan.core.fit.bisection import run
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.units import IEEE_TERMS
from imu_allan.errors import InputError
from imu_allan.report.advice import advice_to_json, axis_lines
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

    Cases: white + B, white + K, white + B + K and white + Gauss-Markov, seeds 1-3 (the
    table of docs/method.md), each resolved term of the model (a term the base record does
    not resolve is no case); the target is half the base record's relative half-width
    without its post-selection part (advisor_cases.rel_halfwidth) and the longer record has a
    new seed.  Why the tolerance is fair: the achieved half-width is itself estimated from one
    record: it divides by the fitted value (which scatters by the target itself, 5-15 %), and
    the term selection of the longer record is random too; a factor 1.5 leaves room for
    that, while a forecast off by more than ~2.3x in time (1.5^2 for a 1/sqrt(T) term) fails
    the case.  Measured: 19 of 23 (B and K sharing one span split unevenly, as before).
    """
    rows = list(cases(seeds=SEEDS))
    assert len(rows) >= 20
    ok = [r for r in rows if r['ok']]
    assert len(ok) >= 0.8 * len(rows), [(r['model'], r['term'], r['ratio']) for r in rows]
    assert all(r['more_s'] > 0 for r in rows)


THESIS_GYROS = {'gyro_x': {'white_noise': 5.759587e-04, 'bias_instability': 1.502922e-04},
                'gyro_y': {'white_noise': 5.730498e-04, 'bias_instability': 1.534920e-04},
                'gyro_z': {'white_noise': 6.021386e-04, 'bias_instability': 1.777327e-04}}


@pytest.mark.parametrize('seconds', [3.0, 60.0, 600.0])
def test_the_advice_says_each_thing_once(seconds):
    """
    The issue's cases: the thesis gyros (white + B) for 3 s, 1 min and 10 min at 100 Hz.

    Per axis one entry for all its open term sets (never one per absent term), every IEEE
    term not resolved as an upper limit, in JSON without NaN; each axis's sentence says
    "cannot tell" at most once; and every limit of a term no open set holds has a time until
    it is resolved or the reason there is none.
    """
    result, fitted = _record(THESIS_GYROS, seconds, seed=0, rate_hz=100.0,
                             axes=tuple(THESIS_GYROS))
    advice = advise(result, fitted)
    assert len({u.axis for u in advice.unresolved}) == len(advice.unresolved)
    for axis in THESIS_GYROS:
        resolved = fitted.resolved(axis)
        assert set(advice.limits[axis]) == {t for t in IEEE_TERMS if t not in resolved}
        for lim in advice.limits[axis].values():
            assert lim.more_s is not None or lim.reason
    doc = advice_to_json(advice)
    json.dumps(doc, allow_nan=False)
    for line in axis_lines(doc).values():
        assert line.count('cannot tell') <= 1, line


def test_an_open_set_separates_when_the_later_of_its_two_directions_does():
    """
    An open set's time is the later direction's, searched on its own (_pair_time skips work).

    Each direction (one set as the truth, fitted with the other) is searched alone here, all
    the way; the set's time must be the later of the two (None if either has none).
    """
    result, fitted = _record(THESIS_GYROS, 600.0, seed=0, rate_hz=100.0,
                             axes=tuple(THESIS_GYROS))
    checked = 0
    for axis in fitted.axes:
        adv = _AxisAdvisor(result, fitted, axis, DEFAULT_TARGETS, analysis_grid())
        n_max = int(adv.n * HORIZON)
        chosen = list(adv.fit.terms)
        times = run(adv._open_sets(n_max))
        for (_differ, n_sep), alt in zip(times, fitted.alternatives(axis)[1:]):
            alt_fit = fit_terms(adv.problem, alt, profile_intervals=False)
            gap = adv._criterion(alt_fit) - adv._criterion(adv.fit)
            start = _nonlinear(alt_fit.terms)
            alone = [run(adv._pair_time([d], gap, start, n_max)) for d in (
                (adv.fit.terms, list(alt), 'fit'), (alt_fit.terms, chosen, '+'.join(alt)))]
            assert n_sep == (None if None in alone else max(alone)), (alt, alone, n_sep)
            checked += 1
    assert checked >= 2


@pytest.mark.parametrize('seed', [3, 4])
def test_every_term_not_resolved_gets_a_time_from_ten_seconds(seed):
    """
    Every term not resolved gets a time from 10 s on: open sets' terms too.

    A GX3-25 from the independent generator (startup_cases: the window, flicker at budget),
    through the node's pipeline for 10, 30 and 60 s: every IEEE term not resolved, an open
    set's too, has a time until one as large as its upper limit is resolved, never "no record
    within reach" (open sets fitted at near-zero sizes never separate; their terms used to get
    no time), and under 100 x the record (a term at its limit is about 2 sigma: it shows soon).
    """
    from core.startup_cases import DEVICE, RATE, unit
    from imu_allan.core.live.online import OnlineAllan
    from imu_allan.core.units import AXES
    import numpy as np
    axes, _ = unit(1.0, np.random.default_rng(seed), 60.0)
    pipeline = OnlineAllan(RATE, AXES, filter_window_s=DEVICE.taps / 1000.0)
    made, opened = 0, 0
    for seconds in (10, 30, 60):
        n = int(seconds * RATE) - made
        pipeline.feed((made + np.arange(n)) / RATE, np.column_stack([a.take(n) for a in axes]))
        made += n
        result = pipeline.result()
        advice = advise(result, pipeline.fit(result))
        for axis, limits in advice.limits.items():
            for term, lim in limits.items():
                opened += lim.in_open_set
                if term == 'quantization':  # beside the filter: never selected, no time
                    assert lim.more_s is None and lim.reason, (seconds, axis, lim)
                    continue
                assert lim.upper_limit is not None, (seconds, axis, term)
                assert lim.more_s is not None and 0.0 < lim.more_s < 100 * seconds, \
                    (seconds, axis, term, lim)
        lines = axis_lines(advice_to_json(advice))
        for line in lines.values():  # only quantization, which the selection leaves out here
            assert all('quantization <' in c for c in line.split('; ')
                       if 'no record within reach resolves' in c), line
    assert opened > 0  # the case this test is for: terms some open sets hold


def test_a_term_as_large_as_its_limit_is_resolved_after_the_advised_time():
    """
    "resolved after about X more if that large" comes true (limit_forecast_cases.py).

    Eight 30-s start-ups of the independent GX3-25: about 30 cases of B and K not resolved,
    each re-simulated at its limit for base + X.  The rule aims at 84 %; measured on 30 seeds
    75 % (open terms) and 48 % (absent ones); these eight seeds give 67 % of 15 and 47 % of
    17.  Required: open terms have a time and come true on at least 40 %, absent ones on at
    least 25 % (the binomial sd on 17 cases is 12 points).  The rule before this test gave
    open terms no time and absent ones one that came true on 1 of these 17 (an absent term's
    gain over the selected set alone, scaled to 4 now).
    """
    from core.limit_forecast_cases import run, shares
    found = shares(run(range(8), 30.0))
    assert found['open'][0] >= 5 and found['open'][1] >= 0.4, found
    assert found['absent'][0] >= 5 and found['absent'][1] >= 0.25, found
