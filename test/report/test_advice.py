"""The advice block of ``analyze --json`` and its closing sentence (report/advice.py)."""

import json

from imu_allan.core.advisor import Advice, DEFAULT_TARGETS, TermAdvice, Unresolved
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
    assert sentence == ('advice: record about 1.5 h more to pin bias instability to 10 % on '
                        'all axes; accel_x cannot yet tell bias instability from rate random '
                        'walk.')


def test_sentence_when_everything_is_met():
    advice = Advice(dict(DEFAULT_TARGETS), 600.0)
    advice.axes['gyro_x'] = {'white_noise': TermAdvice(0.004, 0.0)}
    assert 'no need to record longer' in advice_sentence(advice)


@pytest.mark.parametrize('seconds, text', [(30, 'about 30 s'), (1500, 'about 25 min'),
                                           (5400, 'about 1.5 h'), (3 * 86400, 'about 3 days')])
def test_format_duration(seconds, text):
    assert format_duration(seconds) == text
