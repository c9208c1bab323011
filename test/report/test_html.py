"""The page's words (no browser): the advice headline follows the console's rules."""

from imu_allan.report.html import advice_words

ADVICE = {'targets': {'white_noise': 0.02}, 'record_more_s': 0.0, 'undetected': [],
          'axes': {'gyro_x': {'white_noise': {'rel_halfwidth': 0.001, 'more_s': 0.0}}},
          'unresolved': []}


def test_met_targets_say_no_need_to_record_longer():
    """Every target met, nothing open: the one case that may say so."""
    assert 'no need to record longer' in advice_words(ADVICE)['headline']


def test_open_alternatives_never_say_no_need_to_record_longer():
    """An unresolved term set (or alternatives in the fit) keeps the headline open."""
    open_pair = dict(ADVICE, unresolved=[{'axis': 'gyro_y', 'more_s': None,
                                          'terms': ['white_noise', 'rate_random_walk']}])
    for words in (advice_words(open_pair), advice_words(ADVICE, alternatives=True)):
        assert 'no need' not in words['headline']
        assert 'cannot yet tell' in words['headline']


def test_moving_record_is_told_to_record_at_rest():
    """A moving record: no precision talk, record again at rest."""
    words = advice_words(ADVICE, moving=['gyro_x'])
    assert 'at rest' in words['headline'] and 'no need' not in words['headline']
