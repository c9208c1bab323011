"""The noise-term registry: one TermSpec per term, consistent with the analytic shapes."""

import math

from imu_allan.core.terms import (
    gauss_markov_shape,
    ID_ALPHA,
    model_avar,
    sinusoid_shape,
    TERMS,
)
import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

RATE = 100.0


def test_peak_ratios_are_where_the_shapes_peak():
    """The registry's peak ratios equal the maxima of the shapes (to 1e-6)."""
    gm = minimize_scalar(lambda t: -gauss_markov_shape(t, 1.0), bounds=(0.5, 5.0),
                         method='bounded', options={'xatol': 1e-10}).x
    assert TERMS['gauss_markov'].peak_ratio == pytest.approx(gm, abs=1e-6)
    x = brentq(lambda x: math.tan(x) - 2.0 * x, 1.0, 1.5)  # d/dx sin^2(x)/x = 0
    assert TERMS['sinusoid'].peak_ratio == pytest.approx(x / math.pi, abs=1e-6)
    # and the shape really peaks there
    tau = np.geomspace(0.1, 10.0, 20001)
    assert tau[np.argmax(sinusoid_shape(tau, 1.0))] == pytest.approx(x / math.pi, rel=1e-3)


@pytest.mark.parametrize('name', list(TERMS))
def test_pack_unpack_and_position(name):
    """pack/unpack round trip; hump terms have a position range that brackets their peak."""
    spec = TERMS[name]
    params = spec.pack(2.0, 3.0 if spec.position else None)
    assert tuple(params) == spec.params
    assert spec.unpack(params) == (2.0, 3.0 if spec.position else None)
    if spec.position:
        lo, hi = spec.position_range(1.0, 100.0)
        assert lo < hi
        for pos in (lo, hi):
            peak = pos * spec.peak_ratio if name == 'gauss_markov' else spec.peak_ratio / pos
            assert 1.0 - 1e-12 <= peak <= 100.0 + 1e-9
        assert spec.position_at_peak(10.0) == pytest.approx(
            10.0 / spec.peak_ratio if name == 'gauss_markov' else spec.peak_ratio / 10.0)


def test_avar_is_amplitude_squared_times_shape():
    """avar(params) = amplitude^2 shape, and model_avar sums the terms."""
    tau = np.geomspace(0.01, 100.0, 30)
    terms = {'white_noise': {'value': 2e-3}, 'rate_random_walk': {'value': 1e-5},
             'gauss_markov': {'sigma': 1e-4, 'tau_c': 20.0}}
    total = sum(TERMS[t].unpack(p)[0] ** 2 * TERMS[t].shape(tau, RATE, TERMS[t].unpack(p)[1])
                for t, p in terms.items())
    np.testing.assert_allclose(model_avar(terms, tau, RATE), total, rtol=1e-12)
    np.testing.assert_allclose(TERMS['white_noise'].shape(tau, RATE), 1.0 / tau)


def test_alpha_and_determinism():
    """EDF exponents: the IEEE noise types; ramp and sinusoid deterministic; GM switches."""
    assert [TERMS[t].alpha for t in ('quantization', 'white_noise', 'bias_instability',
                                     'rate_random_walk')] == [2, 0, -1, -2]
    assert TERMS['rate_ramp'].deterministic and TERMS['sinusoid'].deterministic
    assert not TERMS['gauss_markov'].deterministic
    np.testing.assert_array_equal(TERMS['gauss_markov'].alpha_at([1.0, 10.0, 100.0],
                                                                 {'tau_c': 10.0}), [-2, 0, 0])
    assert set(ID_ALPHA) == {'quantization', 'white_noise', 'bias_instability',
                             'rate_random_walk', 'rate_ramp'}


def test_units_from_the_registry():
    """Secondary parameters carry their own units; conventional factors are positive."""
    assert TERMS['gauss_markov'].param_unit('gyro_x', 'tau_c') == 's'
    assert TERMS['sinusoid'].param_unit('accel_y', 'frequency_hz') == 'Hz'
    assert TERMS['gauss_markov'].param_unit('accel_y', 'sigma') == 'm/s^2'
    for spec in TERMS.values():
        for sensor in ('gyro', 'accel'):
            label, factor = spec.conventional[sensor]
            assert label and factor > 0


def test_cosine_integral_series_matches_scipy_sici():
    """Above z = 100 the asymptotic series (no scipy.special import) agrees to 2e-18."""
    from imu_allan.core.terms import cosine_integral
    from scipy.special import sici
    z = np.concatenate([np.geomspace(100.0, 1e9, 5000), [100.0, math.pi * 1000.5]])
    assert np.max(np.abs(cosine_integral(z) - sici(z)[1])) < 2e-18
    small = np.array([0.5, 3.0, 99.0])  # below: scipy's own
    assert np.array_equal(cosine_integral(small), sici(small)[1])


@pytest.mark.parametrize('name', ['quantization', 'white_noise', 'bias_instability',
                                  'rate_random_walk', 'rate_ramp'])
def test_hadamard_shape_matches_the_ohdev_of_simulated_data(name):
    """
    The OHVAR of each simulated term, averaged over 6 records, is its Hadamard shape.

    6 records of 100 000 samples at 100 Hz; at tau = 0.01-1 s the estimates have hundreds of
    degrees of freedom or more each (flicker and random walk: >= 150 at 1 s), so the mean of 6
    lies within 8 % of the truth far beyond 3 standard deviations (<= 4 %); a ramp's is 0
    (to rounding: 1e-20 of the rate squared).
    """
    from imu_allan.core.deviations import deviation
    from imu_allan.core.simulation.simulate import simulate_axis
    from imu_allan.core.terms import hadamard_shape
    rng = np.random.default_rng(11)
    data = np.column_stack([simulate_axis({name: {'value': 1.0}}, 100_000, 100.0, rng)
                            for _ in range(6)])
    ohdev = deviation(data, 100.0, 'ohdev', taus=[0.01, 0.03, 0.1, 0.3, 1.0])
    measured = np.mean(ohdev.dev ** 2, axis=1)
    expected = hadamard_shape(name, ohdev.tau, 100.0)
    if name == 'rate_ramp':
        assert np.all(measured < 1e-20 * np.max(data) ** 2)
        assert np.all(expected == 0.0)
    else:
        np.testing.assert_allclose(measured, expected, rtol=0.08)


def test_hadamard_flicker_tends_to_its_floor():
    """The sampled flicker HVAR tends to (4 ln 2 - 1.5 ln 3) / pi (0.1 % at m = 100)."""
    from imu_allan.core.terms import HADAMARD_FLICKER_FLOOR, hadamard_shape
    assert HADAMARD_FLICKER_FLOOR == pytest.approx(0.357994, abs=1e-6)
    assert hadamard_shape('bias_instability', 1.0, 100.0) == pytest.approx(
        HADAMARD_FLICKER_FLOOR, rel=1e-3)
