"""
``analyze`` on a record of a moving IMU: the numbers are the motion's, not noise coefficients.

The real 61 s Jackal recording (test2.bag, shared data; skipped when absent) is called moving by
the verdict.  Without ``--allow-motion`` the summary says what the numbers are and gives no
intervals, the Kalibr line and file hold no values, and the advice is to record at rest; with
it, the Kalibr values come back.
"""

import json

from conftest import run_command
import pytest

pytestmark = pytest.mark.ros


def _bag(shared_data):
    return shared_data / 'bags' / 'test2.bag'


@pytest.mark.slow
def test_moving_record_is_not_a_noise_measurement(shared_data, tmp_path):
    proc = run_command('analyze', _bag(shared_data), '--out', tmp_path / 'out')
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    assert 'NOT static (moving)' in text
    assert 'the IMU MOVED: these curves measure the motion' in text
    assert '68.3 % intervals' not in text and '(motion)' in text
    assert 'Kalibr (continuous-time, worst axis): not given: the IMU moved' in text
    assert 'record again at rest' in text and 'no need to record longer' not in text
    yaml = (tmp_path / 'out' / 'imu.yaml').read_text()
    assert 'gyroscope_noise_density: null' in yaml
    assert 'accelerometer_random_walk: null' in yaml


def test_allow_motion_exports_the_motion_numbers(shared_data):
    proc = run_command('analyze', _bag(shared_data), '--json', '--allow-motion')
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report['verdict']['static'] is False
    assert report['kalibr']['gyroscope_noise_density'] > 0
    proc = run_command('analyze', _bag(shared_data), '--json')
    assert json.loads(proc.stdout)['kalibr']['gyroscope_noise_density'] is None
