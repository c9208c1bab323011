"""Warm-up detection: a settling bias at the start, and none on static records."""

import math

from imu_allan.core.analysis import analyze_samples
from imu_allan.core.checks.warmup import find_warmup, warmup_sentence
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.simulation.simulate import simulate
from imu_allan.formats.samples import Samples
from imu_allan.report.json_report import analysis_to_json, console_summary
import numpy as np
import pytest

RATE = 20.0
HOURS = 2.0


def _static_model():
    """Return the usual static model: thesis 3DM-GX3-25 (white + flicker) + a rate random walk."""
    model = thesis_gx3_25_model()
    for axis in model.axes:
        model.terms[axis]['rate_random_walk'] = {'value': 2e-6 if 'gyro' in axis else 2e-5}
    return model


def _record(seed, tau_c=None):
    model = _static_model()
    data = simulate(model, int(HOURS * 3600 * RATE), RATE, seed=seed)
    if tau_c:  # a settling of 0.17 deg/s and 0.03 m/s^2, about 20-40 x sigma_A(tau_c)
        t = np.arange(data.shape[0]) / RATE
        amp = np.array([3e-3] * 3 + [3e-2] * 3)
        data += amp * np.exp(-t / tau_c)[:, None]
    return model, data


@pytest.mark.parametrize('tau_c', [180.0, 300.0, 600.0])
def test_warmup_found_within_a_factor_two_of_three_time_constants(tau_c):
    """The goal: 3-10 min time constants, three seeds each."""
    for seed in range(3):
        model, data = _record(seed, tau_c)
        warm, details = find_warmup(data, RATE, model.axes)
        assert 0.5 < warm / (3 * tau_c) < 2.0, details


def test_no_warmup_on_static_records():
    """
    Flicker + random walk are not a warm-up: 8 static 2-h records x 6 axes.

    The largest amplitude z seen on 24 such records was 12 (threshold 15).
    """
    for seed in range(100, 108):
        model, data = _record(seed)
        warm, details = find_warmup(data, RATE, model.axes)
        assert warm == 0.0, details


def test_analysis_leaves_the_warmup_out_and_says_so():
    """analyze_samples cuts the settling start; JSON verdict and console line carry it."""
    model, data = _record(7, 300.0)
    t = np.arange(data.shape[0]) / RATE
    analysis = analyze_samples(Samples(t=t, data=data, axes=list(model.axes), source='warm'))
    assert 450.0 < analysis.warmup_s < 1800.0
    assert analysis.n_samples == data.shape[0] - int(round(analysis.warmup_s * RATE))
    report = analysis_to_json(analysis)
    assert report['verdict']['warmup_s'] == analysis.warmup_s
    minutes = f'first {analysis.warmup_s / 60:.0f} min left out: the bias was settling'
    assert minutes in console_summary(analysis)
    assert warmup_sentence(0.0) == ''
    static = analyze_samples(Samples(t=t, data=_record(8)[1], axes=list(model.axes),
                                     source='static'))
    assert static.warmup_s == 0.0 and math.isfinite(static.duration_s)
    assert analysis_to_json(static)['verdict']['warmup_s'] == 0.0
