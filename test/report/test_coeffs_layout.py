"""
The topic layouts: encode (the node's tables) then decode (monitor, users) round trip.

Built on a real fit of 5 min of simulated 100 Hz data (fixed seed, about 5 s), so the tables
hold detected and undetected (NaN) terms.
"""

import math

from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.model import NoiseModel
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.units import AXES, conventional, IEEE_TERMS, si_unit
from imu_allan.errors import InputError
from imu_allan.report.coeffs_layout import (
    COEFF_LABELS,
    coefficient_table,
    coefficient_terms,
    decode_coefficients,
    decode_deviation,
    DEVIATION_LABELS,
    deviation_table,
)
import numpy as np
import pytest

MODEL = NoiseModel.from_dict({'gyro': {'white_noise': 5.0e-4, 'bias_instability': 8.0e-4},
                              'accel': {'white_noise': 8.0e-4}})


@pytest.fixture(scope='module')
def estimate():
    n, rate = 30_000, 100.0  # 5 min; two fixed terms keep the fit short (about 3 s)
    pipe = OnlineAllan(rate, axes=AXES, terms=['white_noise', 'bias_instability'])
    pipe.feed(np.arange(n) / rate, simulate(MODEL, n, rate, seed=5))
    result = pipe.result()
    return result, pipe.fit(result)


class Layout:
    """A message-like object with the Float64MultiArray field names (as rosbags gives)."""

    def __init__(self, table, labels, offset=0):
        class Dim:
            def __init__(self, label, size):
                self.label, self.size = label, size
        self.layout = type('L', (), {})()
        self.layout.dim = [Dim(label, size) for label, size in zip(labels, table.shape)]
        self.layout.data_offset = offset
        self.data = table.ravel().tolist()


def test_round_trip_message_and_flat(estimate):
    result, fitted = estimate
    table = coefficient_table(fitted)
    assert np.isnan(table).any() and np.isfinite(table).any()
    from_msg = decode_coefficients(Layout(table, COEFF_LABELS))
    from_flat = decode_coefficients(table.ravel(), list(zip(COEFF_LABELS, table.shape)))
    np.testing.assert_array_equal(from_msg, table)
    np.testing.assert_array_equal(from_flat, table)
    dev = deviation_table(result)
    tau, adev = decode_deviation(Layout(dev, DEVIATION_LABELS))
    np.testing.assert_array_equal(tau, result.tau)
    np.testing.assert_array_equal(adev, result.adev)


def test_terms_in_analyze_json_shape(estimate):
    _, fitted = estimate
    table = coefficient_table(fitted)
    terms = coefficient_terms(table)
    assert list(terms) == list(AXES)
    for i, axis in enumerate(AXES):
        detected = [t for j, t in enumerate(IEEE_TERMS) if math.isfinite(table[i, j, 0])]
        assert list(terms[axis]) == detected
        for term in detected:
            entry = terms[axis][term]
            assert entry['value'] == fitted.value(axis, term)
            assert entry['ci'] == list(fitted.interval(axis, term))
            assert entry['unit'] == si_unit(axis, term)
            assert entry['conventional']['value'] == conventional(axis, term,
                                                                  entry['value'])[0]


@pytest.mark.parametrize('labels, shape, offset, problem', [
    (('axis', 'stat', 'term'), (6, 3, 5), 0, 'labels'),
    (COEFF_LABELS, (6, 4, 3), 0, 'sizes'),
    (COEFF_LABELS, (6, 5, 3), 2, 'data_offset'),
])
def test_wrong_layout_names_the_topic(labels, shape, offset, problem):
    with pytest.raises(InputError, match=f'imu/allan_coeffs.*{problem}'):
        decode_coefficients(Layout(np.zeros(shape), labels, offset))


def test_data_not_matching_dims():
    with pytest.raises(InputError, match='imu/allan_coeffs'):
        decode_coefficients(np.zeros(89), list(zip(COEFF_LABELS, (6, 5, 3))))
    with pytest.raises(InputError, match='imu/allan_deviation.*rows'):
        decode_deviation(np.zeros(12), list(zip(DEVIATION_LABELS, (6, 2))))
