"""The advice block of ``analyze --json`` and the one renderer of its words (report/advice.py)."""

import json
import math

from imu_allan.core.fit.advisor import Advice, DEFAULT_TARGETS, Limit, TermAdvice, Unresolved
from imu_allan.core.live import health
from imu_allan.report.advice import (
    advice_sentence,
    advice_statuses,
    advice_to_json,
    axis_lines,
    format_duration,
)
import pytest

NB = ('white_noise', 'bias_instability')
NK = ('white_noise', 'rate_random_walk')


def _advice():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    for axis in ('gyro_x', 'accel_x'):
        advice.axes[axis] = {'white_noise': TermAdvice(0.004, 0.0),
                             'bias_instability': TermAdvice(0.2, 5400.0)}
        advice.limits[axis] = {'rate_ramp': Limit(1e-6, 120.0)}
    advice.axes['accel_x'].pop('bias_instability')
    advice.limits['accel_x'].update({'bias_instability': Limit(2e-4, 1800.0, in_open_set=True),
                                     'rate_random_walk': Limit(3e-5, 1800.0, in_open_set=True)})
    advice.unresolved.append(Unresolved('accel_x', ('bias_instability', 'rate_random_walk'),
                                        1800.0, sets=(NB, NK)))
    return advice


def test_json_block_has_the_contract_keys_and_no_nan():
    doc = advice_to_json(_advice())
    assert set(doc) >= {'targets', 'axes', 'unresolved', 'record_more_s', 'undetected'}
    assert doc['targets'] == DEFAULT_TARGETS
    assert doc['axes']['gyro_x']['white_noise'] == {'rel_halfwidth': 0.004, 'more_s': 0.0}
    assert {'axis': 'gyro_x', 'term': 'rate_ramp', 'upper_limit': 1e-6, 'unit': 'rad/s^2',
            'open': False, 'more_s': 120.0} in doc['undetected']
    assert doc['unresolved'] == [{'axis': 'accel_x',
                                  'terms': ['bias_instability', 'rate_random_walk'],
                                  'sets': [list(NB), list(NK)], 'more_s': 1800.0}]
    assert doc['record_more_s'] == 5400.0
    json.dumps(doc, allow_nan=False)


def test_null_more_s_carries_a_reason():
    advice = _advice()
    advice.axes['gyro_x']['bias_instability'] = TermAdvice(0.9, None, 'not reached')
    doc = advice_to_json(advice)
    entry = doc['axes']['gyro_x']['bias_instability']
    assert entry['more_s'] is None and entry['reason'] == 'not reached'
    json.dumps(doc, allow_nan=False)


def test_each_axis_says_its_open_sets_once_with_why_and_how_long():
    lines = axis_lines(advice_to_json(_advice()))
    assert lines['accel_x'].count('cannot tell yet') == 1
    assert ('cannot tell yet bias instability or rate random walk beside white noise (both '
            'lift the longest averaging times); about 30 min more decides') in lines['accel_x']
    # an open term is a limit too, with the time until a term that large is resolved
    assert ('bias instability < 0.72 m/s/h (95 %), resolved after about 30 min more if that '
            'large') in lines['accel_x']
    # an absent term: its limit and the time until one that large is resolved
    assert ('rate ramp < 743 deg/h^2 (95 %), resolved after about 2 min more if that large'
            in lines['gyro_x'])
    assert 'white noise ±0.4 % (target 2 % met)' in lines['gyro_x']
    assert 'bias instability ±20 % (target 10 %: about 1.5 h more reaches it)' in lines['gyro_x']


def test_the_sentence_and_the_statuses_are_the_same_words():
    advice = _advice()
    sentence = advice_sentence(advice_to_json(advice))
    statuses = advice_statuses(advice, 'allan: recording advice', 'allan: ')
    assert statuses[0].name == 'allan: recording advice' and statuses[0].level == health.WARN
    for status in statuses[1:]:
        axis = status.name.removeprefix('allan: ').removesuffix(' advice')
        assert f'{axis}: {status.message}.' in sentence
    assert statuses[0].message in sentence
    by_axis = {s.name: s for s in statuses}
    values = by_axis['allan: accel_x advice'].values
    assert values['bias_instability.upper_limit'] == 2e-4
    assert values['rate_ramp.resolve_s'] == 120.0
    assert advice_statuses(None, 'allan: recording advice')[0].level == health.STALE


def test_met_targets_and_nothing_open_is_ok_and_says_no_need():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    statuses = advice_statuses(advice, 'allan: recording advice')
    assert [s.level for s in statuses] == [health.OK, health.OK]
    assert 'no need to record longer' in advice_sentence(advice_to_json(advice))
    unknown = Advice(dict(DEFAULT_TARGETS), 600.0)
    unknown.axes['gyro_x'] = {'white_noise': TermAdvice(0.9, None, 'not reached')}
    statuses = advice_statuses(unknown, 'allan: recording advice')
    assert statuses[0].level == health.WARN
    assert math.isnan(statuses[1].values['white_noise.more_s'])


def test_an_open_set_is_never_no_need_to_record_longer():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    advice.unresolved.append(Unresolved('gyro_x', ('rate_random_walk',), None,
                                        'not told apart within 1e+04 x the record',
                                        (('white_noise',), NK)))
    sentence = advice_sentence(advice_to_json(advice))
    assert 'no need' not in sentence
    assert 'cannot tell yet rate random walk or none' in sentence
    assert 'no record within reach decides at their fitted sizes (see each term at its limit)' \
        in sentence


def test_a_moving_record_is_told_to_record_at_rest():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    advice.moving = ['gyro_z']
    sentence = advice_sentence(advice_to_json(advice))
    assert 'record again at rest' in sentence and 'no need' not in sentence


@pytest.mark.parametrize('seconds, text', [(30, 'about 30 s'), (1500, 'about 25 min'),
                                           (5400, 'about 1.5 h'), (3 * 86400, 'about 3 days')])
def test_format_duration(seconds, text):
    assert format_duration(seconds) == text


def test_three_open_terms_are_one_clause_with_each_reason_once():
    """B, K or R beside N (a 10-s record): one clause, each reason once, no 'both' for three."""
    advice = Advice(dict(DEFAULT_TARGETS), 10.0)
    advice.axes['gyro_y'] = {'white_noise': TermAdvice(0.08, 70.0)}
    sets = (('white_noise', 'bias_instability'), ('white_noise', 'rate_random_walk'),
            ('white_noise', 'rate_ramp'))
    advice.unresolved.append(Unresolved('gyro_y', ('bias_instability', 'rate_random_walk',
                                                   'rate_ramp'), None, 'a reason', sets))
    line = axis_lines(advice_to_json(advice))['gyro_y']
    assert line.count('cannot tell yet') == 1, line
    assert 'which of bias instability, rate random walk or rate ramp beside white noise' in line
    assert 'both' not in line and line.count('they all lift the longest averaging times') == 1, \
        line
