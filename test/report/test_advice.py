"""The advice block of ``analyze --json`` and its closing sentence (report/advice.py)."""

import json

from imu_allan.core.fit.advisor import Advice, DEFAULT_TARGETS, TermAdvice, Unresolved
from imu_allan.report.advice import advice_sentence, advice_to_json, format_duration
import pytest


def _advice():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    for axis in ('gyro_x', 'accel_x'):
        advice.axes[axis] = {'white_noise': TermAdvice(0.004, 0.0),
                             'bias_instability': TermAdvice(0.2, 5400.0),
                             'rate_ramp': TermAdvice(None, 120.0, detected=False,
                                                     upper_limit=1e-6)}
    advice.unresolved.append(Unresolved('accel_x', ('bias_instability', 'rate_random_walk'),
                                        1800.0))
    return advice


def test_json_block_has_the_contract_keys():
    doc = advice_to_json(_advice())
    assert set(doc) >= {'targets', 'axes', 'unresolved', 'record_more_s'}
    assert doc['targets'] == DEFAULT_TARGETS
    assert doc['axes']['gyro_x']['white_noise'] == {'rel_halfwidth': 0.004, 'more_s': 0.0}
    assert 'rate_ramp' not in doc['axes']['gyro_x']  # undetected terms are listed apart
    assert doc['undetected'][0] == {'axis': 'gyro_x', 'term': 'rate_ramp',
                                    'upper_limit': 1e-6, 'unit': 'rad/s^2', 'more_s': 120.0}
    assert doc['unresolved'] == [{'axis': 'accel_x',
                                  'terms': ['bias_instability', 'rate_random_walk'],
                                  'more_s': 1800.0}]
    assert doc['record_more_s'] == 5400.0


def test_null_more_s_carries_a_reason():
    advice = _advice()
    advice.axes['gyro_x']['bias_instability'] = TermAdvice(0.9, None, 'not reached')
    doc = advice_to_json(advice)
    entry = doc['axes']['gyro_x']['bias_instability']
    assert entry['more_s'] is None and entry['reason'] == 'not reached'
    json.dumps(doc, allow_nan=False)


def test_sentence_names_the_time_the_term_and_the_pair():
    sentence = advice_sentence(_advice())
    # each open alternative in words with its own time (issue 22: "rate random walk or rate
    # ramp: cannot tell yet; record about 4 h more"), no longer one clause per pair of terms
    assert sentence == ('advice: record about 1.5 h more to pin bias instability to 10 % on '
                        'all axes; accel_x: bias instability or rate random walk: cannot tell '
                        'yet; record about 30 min more.')


def test_an_open_alternative_is_never_no_need_to_record_longer():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    advice.unresolved.append(Unresolved('gyro_x', ('rate_random_walk',), None,
                                        'not separated within 1e+04 x the record',
                                        ('white_noise', 'bias_instability',
                                         'rate_random_walk')))
    sentence = advice_sentence(advice)
    assert 'no need' not in sentence
    assert 'gyro_x: rate random walk or none: cannot tell yet' in sentence
    assert advice_to_json(advice)['unresolved'][0]['alternative'] == [
        'white_noise', 'bias_instability', 'rate_random_walk']


def test_a_moving_record_is_told_to_record_at_rest():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    advice.moving = ['gyro_z']
    sentence = advice_sentence(advice)
    assert 'record again at rest' in sentence and 'no need' not in sentence


def test_sentence_when_everything_is_met():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    assert 'no need to record longer' in advice_sentence(advice)


@pytest.mark.parametrize('seconds, text', [(30, 'about 30 s'), (1500, 'about 25 min'),
                                           (5400, 'about 1.5 h'), (3 * 86400, 'about 3 days')])
def test_format_duration(seconds, text):
    assert format_duration(seconds) == text
