"""core.temperature: profiles, bias-versus-temperature slopes and their intervals, moves."""

from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
from imu_allan.core.temperature import (
    bias_slopes,
    coinciding_change,
    regress_slopes,
    temperature_changes,
    TemperatureProfile,
)
from imu_allan.core.units import AXES
import numpy as np
import pytest


def test_profiles():
    """constant, ramp and warm-up follow their formulas; bad specifications are refused."""
    const = TemperatureProfile.parse('constant:30')
    assert const.at(0.0) == const.at(1e6) == 30.0
    ramp = TemperatureProfile.parse('ramp:20:40:100')
    assert ramp.at(-5.0) == 20.0 and ramp.at(50.0) == 30.0 and ramp.at(1000.0) == 40.0
    warm = TemperatureProfile.parse('warmup:20:45:300')
    assert warm.at(0.0) == 20.0
    assert warm.at(300.0) == pytest.approx(45 - 25 / np.e)
    assert np.allclose(warm.at(np.array([0.0, 3000.0])), [20.0, 45.0], atol=1e-3)
    for bad in ('hot', 'ramp:20:40', 'ramp:20:40:0', 'constant:x', 'warmup:20:200:5',
                'constant:nan'):
        with pytest.raises(ValueError, match='temperature profile'):
            TemperatureProfile.parse(bad)


def test_regression_is_exact_without_noise():
    """A rate that is exactly b * T gives b (per column); the white error is 0."""
    x = np.linspace(20, 40, 50)
    y = np.stack([3e-4 * x + 1.0, -2e-3 * x], axis=1)
    slope, se = regress_slopes(x, y)
    assert np.allclose(slope, [3e-4, -2e-3], rtol=1e-12)
    assert np.allclose(se, 0, atol=1e-15)


def test_refusals():
    """No overlap, too small a temperature change, too few readings: a reason, no slope."""
    t = np.arange(20000) / 100.0
    data = np.zeros((t.size, 1))
    assert bias_slopes(t, data, 100.0, ('gyro_x',), [1000, 1001], [20, 30], replicas=5)[0] == {}
    out, notes = bias_slopes(t, data, 100.0, ('gyro_x',), [0, 200], [25, 25.1], replicas=5)
    assert out == {} and 'moved by 0.10' in notes[0]
    assert bias_slopes(t, data, 100.0, ('gyro_x',), [5], [25], replicas=5)[0] == {}


@pytest.mark.slow
def test_slope_intervals_cover_the_truth():
    """
    Simulated 3DM-GX3-25 noise (white + flicker) plus known slopes on a temperature ramp.

    12 records of 10 min, 6 axes: 72 normalised errors z = (estimate - truth) / stderr.  With
    a calibrated standard error their rms is 1; for 72 values its sampling std is about
    1/sqrt(144) = 0.08, so [0.7, 1.35] is a 4-sigma band (a little wider above: the fitted
    model's own error widens the tails).  The textbook independent-blocks error (what
    ``regress_slopes`` returns) gives an rms near 2-3 here: the test can fail.  Fixed seeds.
    """
    rate, duration = 100.0, 600.0
    n = int(rate * duration)
    t = np.arange(n) / rate
    profile = TemperatureProfile.parse('ramp:20:35:600')
    truth = np.array([1e-4, -2e-4, 5e-5, 1e-3, -2e-3, 0.0])
    temp_t = np.arange(0.0, duration + 1, 1.0)
    temp_c = profile.at(temp_t)
    model = thesis_gx3_25_model()
    z, z_white = [], []
    for seed in range(12):
        data = simulate(model, n, rate, seed=seed) + np.outer(profile.at(t) - 20.0, truth)
        est, notes = bias_slopes(t, data, rate, AXES, temp_t, temp_c, replicas=200,
                                 seed=seed)
        assert notes == [] and set(est) == set(AXES)
        z += [(est[a].value - truth[j]) / est[a].stderr for j, a in enumerate(AXES)]
        x = np.interp(np.arange(64) * 9.375 + 4.6875, temp_t, temp_c)
        means = data[:64 * 937].reshape(64, 937, 6).mean(axis=1)
        slope, white = regress_slopes(x, means)
        z_white += list((slope - truth) / white)
        assert est['gyro_x'].unit == 'rad/s/K' and est['accel_y'].unit == 'm/s^2/K'
        lo, hi = est['gyro_x'].ci
        assert lo < est['gyro_x'].value < hi
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.7 < rms < 1.35, rms
    assert float(np.sqrt(np.mean(np.square(z_white)))) > 1.5


def test_slope_intervals_on_a_short_ramp_record():
    """
    36-s records whose 20 -> 40 deg C ramp (over 30 s) fills them, as the driver test records.

    Thesis 3DM-GX3-25 noise at 100 Hz, gyro slopes 5e-4, -3e-4, 0 rad/s/K, temperature every
    0.5 s in 0.063 deg C steps; 20 records x 6 axes = 120 normalised errors.  Calibrated, their
    rms is 1 with a sampling std of about 1/sqrt(240) = 0.065, so [0.78, 1.22] is a 3.4-sigma
    band.  With the BIC-selected noise model (which drops the flicker a 36-s record cannot
    resolve) the rms of these 120 was 1.38 (coverage 61 %); it is 1.05 (68 %) with every term
    fitted (module docstring of core.temperature).  Fixed seeds.
    """
    rate, n = 100.0, 3600
    t = np.arange(1, n + 1) / rate
    profile = TemperatureProfile.parse('ramp:20:40:30')
    truth = np.array([5e-4, -3e-4, 0.0, 0.0, 0.0, 0.0])
    temp_t = np.arange(0.5, 36.0 + 1e-9, 0.5)
    temp_c = np.round(profile.at(temp_t) / 0.063) * 0.063
    model = thesis_gx3_25_model()
    z = []
    for seed in range(20):
        data = simulate(model, n, rate, seed=100 + seed) + np.outer(profile.at(t) - 20.0, truth)
        est, notes = bias_slopes(t, data, rate, AXES, temp_t, temp_c, seed=seed)
        assert notes == []
        z += [(est[a].value - truth[j]) / est[a].stderr for j, a in enumerate(AXES)]
    rms = float(np.sqrt(np.mean(np.square(z))))
    assert 0.78 < rms < 1.22, rms
    assert abs(float(np.mean(z))) < 0.3      # no bias: 3.3 sigma of the mean of 120


def test_changes_ramp_plateau_and_noise():
    """Up 10 deg C, plateau, down 5, with quantization steps and small wiggles."""
    t = np.arange(0.0, 3000.0, 1.0)
    temp = np.interp(t, [0, 500, 1000, 2000, 2200, 3000], [20, 20, 30, 30, 25, 25])
    temp = temp + 0.3 * np.sin(t / 7.0)           # wiggles below the 1 deg C threshold
    temp = np.round(temp / 0.063) * 0.063         # ADC steps of the GX3-25 sensor
    moves = temperature_changes(t, temp)
    assert len(moves) == 2
    up, down = moves
    assert up.to_c - up.from_c == pytest.approx(10.0, abs=0.2)   # wiggles smoothed away
    assert 450 <= up.t_start_s <= 600 and 900 <= up.t_end_s <= 1010
    assert down.to_c < down.from_c and 1990 <= down.t_start_s <= 2080
    assert 2100 <= down.t_end_s <= 2230
    assert coinciding_change(750.0, moves) == 0
    t_end = up.t_end_s
    assert coinciding_change(2100.0, moves) == 1
    assert coinciding_change(1500.0, moves) is None
    assert coinciding_change(t_end + 15.0, moves, margin_s=20.0) == 0
    assert temperature_changes(t, 25.0 + 0.3 * np.sin(t)) == []


def test_changes_warmup_ends_near_the_plateau():
    """
    An exponential warm-up (tau 300 s): its 10-90 % span is tau ln(10/9) .. tau ln(10).

    Both ends come later by up to the 30 s half-width of the smoothing: at the record's first
    reading the one-sided 60 s mean already sits above the starting level, which also
    shrinks the 10 % settling band.
    """
    t = np.arange(0.0, 3600.0, 1.0)
    temp = TemperatureProfile.parse('warmup:20:45:300').at(t)
    (move,) = temperature_changes(t, temp)
    assert 300 * np.log(10 / 9) - 2 <= move.t_start_s <= 300 * np.log(10 / 9) + 30
    assert 300 * np.log(10) - 2 <= move.t_end_s <= 300 * np.log(10) + 30
    assert move.to_json()['from_c'] == move.from_c < 21.5     # the first 30 s mean


def test_temperature_range_all_and_window():
    """Whole estimate: min/max of every reading; sliding window: of the last window_s s."""
    from imu_allan.core.temperature import TemperatureRange
    whole, window = TemperatureRange(), TemperatureRange(window_s=10.0)
    assert np.isnan(whole.key_values()['temperature_min_c'])
    for t, c in ((0, 30.0), (5, 20.0), (12, 25.0), (14, float('nan')), (16, 26.0)):
        whole.add(t, c)
        window.add(t, c)
    assert whole.key_values() == {'temperature_min_c': 20.0, 'temperature_max_c': 30.0}
    # The window at t = 16 s holds the readings of 6..16 s: 25 and 26.
    assert window.key_values() == {'temperature_min_c': 25.0, 'temperature_max_c': 26.0}
    window.add(30.0, 24.0)
    assert window.key_values() == {'temperature_min_c': 24.0, 'temperature_max_c': 24.0}
    whole.reset()
    assert whole.count == 0 and np.isnan(whole.high)


def test_changes_false_alarms_and_detection():
    """
    False alarms and detection of temperature moves on simulated 10 h records.

    20 x 10 h at 1 Hz of a still board: 25 deg C +- 0.4 (1 h sine) + noise of 2 ADC codes,
    coded as the GX3-25 sends it: no move (the swings stay under 1 deg C after the 60 s mean).
    20 records with a 1.5 deg C rise over 10 min at 5 h: each found once, span within 5 min.
    Fixed seed.  (Measured over 50 + 50 such records: 0 false moves, 50 of 50 found.)
    """
    from imu_allan.device import gx3_protocol as p
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 36000.0, 1.0)
    false_moves = found = 0
    for _ in range(20):
        still = 25 + 0.4 * np.sin(2 * np.pi * t / 3600 + rng.uniform(0, 6.3))
        noisy = still + 0.126 * rng.standard_normal(t.size)
        false_moves += len(temperature_changes(t, p.counts_to_celsius(
            p.celsius_to_counts(noisy))))
        rise = 25 + 1.5 * np.clip((t - 18000) / 600, 0, 1) + 0.126 * rng.standard_normal(t.size)
        moves = temperature_changes(t, p.counts_to_celsius(p.celsius_to_counts(rise)))
        found += (len(moves) == 1 and abs(moves[0].t_start_s - 18000) < 300
                  and abs(moves[0].t_end_s - 18600) < 300)
    assert false_moves == 0 and found == 20
