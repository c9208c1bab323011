"""
A measured sample rate (rate_hz 0): RateFinder and OnlineAllan.

Deterministic stamps and seeded data; all comparisons are exact or at float rounding.
"""

from imu_allan.core.live.health import RateFinder
from imu_allan.core.live.online import OnlineAllan
from imu_allan.core.units import AXES
from imu_allan.errors import InputError
import numpy as np
import pytest


def _stream(rate, seconds, seed=0, t0=1_700_000_000.0):
    n = int(rate * seconds)
    return t0 + np.arange(n) / rate, np.random.default_rng(seed).normal(scale=1e-3, size=(n, 6))


def test_rate_from_the_first_seconds_whatever_the_batches():
    """Same rate for one batch or many; fixed after 2 s of stamps; nothing lost."""
    t, data = _stream(400.0, 5.0)
    t[1000:] += 0.5  # a later change of spacing must not matter: only the first 2 s count
    whole = RateFinder()
    assert whole.add(t, data) == pytest.approx(400.0, rel=1e-4)
    pieces = RateFinder()
    rates = [pieces.add(t[i:i + 37], data[i:i + 37]) for i in range(0, 1000, 37)]
    assert rates[:21] == [None] * 21  # 21 x 37 samples = 1.94 s of stamps
    assert rates[-1] == whole.rate_hz
    held_t, held = pieces.take()
    np.testing.assert_array_equal(held_t, t[:held_t.size])
    np.testing.assert_array_equal(held, data[:held_t.size])
    assert pieces.n_held == 0


def test_measured_equals_configured_at_that_rate():
    """Samples held while measuring are all fed: the estimate equals a configured run."""
    t, data = _stream(200.0, 60.0, seed=1)
    measured = OnlineAllan(0.0, AXES)
    for i in range(0, t.size, 150):
        measured.feed(t[i:i + 150], data[i:i + 150])
    configured = OnlineAllan(measured.rate_hz, AXES)
    configured.feed(t, data)
    assert measured.rate_source == 'measured' and configured.rate_source == 'configured'
    a, b = measured.result(), configured.result()
    np.testing.assert_array_equal(a.tau, b.tau)
    np.testing.assert_array_equal(a.avar, b.avar)
    assert measured.monitor.n_kept == t.size  # every held sample went through
    assert measured.estimator.n_offered == configured.estimator.n_offered
    health = measured.stream_health(0.0)
    assert health.values['rate_source'] == 'measured'
    assert health.values['tau0_s'] == pytest.approx(1 / 200.0, rel=1e-4)


def test_stale_while_measuring_and_misfit_options_named():
    """STALE until the rate is known; a measured rate too low for the gate window: InputError."""
    t, data = _stream(10.0, 3.0)
    pipeline = OnlineAllan(0.0, AXES, gate_options={'window_s': 0.2})
    pipeline.feed(t[:5], data[:5])
    assert pipeline.stream_health(0.0).level == 3 and pipeline.result() is None
    with pytest.raises(InputError, match='gate_window_s'):
        pipeline.feed(t[5:], data[5:])
