"""
``analyze --online`` gives exactly the allan node's numbers for the same samples.

test_allan_node shows over DDS that the node publishes what ``OnlineAllan`` computes with the
node's parameters; this test closes the chain: ``analyze --online`` on the same samples equals
that ``OnlineAllan`` to the last bit (both deviations and fitted terms).
"""

import json

from conftest import run_command
from imu_allan import simulate, thesis_gx3_25_model
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.live.session import pipeline_options
from imu_allan.core.units import AXES, IEEE_TERMS
from imu_allan.formats.csv_samples import write_csv
from imu_allan.formats.samples import Samples
from imu_allan.nodes.allan_parameters import _DEFAULTS
from imu_allan.report.coeffs_layout import coefficient_table
import numpy as np
import pytest

pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_analyze_online_equals_the_node_pipeline(tmp_path):
    n = 100 * 1200
    data = simulate(thesis_gx3_25_model(), n, 100.0, seed=31)
    data[:, 5] += 9.80665
    t = 1000.0 + np.arange(n) / 100.0
    path = tmp_path / 'still.csv'
    write_csv(path, Samples(t=t, data=data))

    node = OnlineAllan(axes=AXES, **pipeline_options(dict(_DEFAULTS, rate_hz=100.0)))
    node.feed(t, data)
    result = node.result()
    expected = coefficient_table(node.fit(result), AXES)

    # the node is configured with rate_hz = 100; analyze takes the same rate with --rate
    proc = run_command('analyze', path, '--online', '--rate', '100', '--json')
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    for j, axis in enumerate(AXES):
        entry = report['axes'][axis]
        np.testing.assert_array_equal(entry['adev']['tau'], result.tau)
        np.testing.assert_array_equal(entry['adev']['adev'], result.adev[:, j])
        for k, term in enumerate(IEEE_TERMS):
            value = entry['terms'].get(term, {}).get('value', np.nan)
            np.testing.assert_array_equal(value, expected[j, k, 0])
