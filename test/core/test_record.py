"""
``analyze_record``: one call computes every part of a record's analysis, each named.

The record is generated here, not with the package's simulator: white noise and a rate
random walk from numpy's generator (fixed seed), plus a bias settling exp(-t / 300 s) at the
start, which the warm-up detector leaves out (about 3 time constants, 871 s with this seed).
2 h at 20 Hz, six axes.
"""

import math

from imu_allan.core.analysis import AnalysisOptions
from imu_allan.core.overbound import HorizonError
from imu_allan.core.record import (
    analyze_record,
    OverboundRequest,
    RecordAnalysis,
    RecordOptions,
)
from imu_allan.core.units import AXES
from imu_allan.formats.samples import Samples, Temperatures
import numpy as np
import pytest

RATE = 20.0
N = int(2 * 3600 * RATE)
T0 = 1_700_000_000.0
WHITE_WALK = ('white_noise', 'rate_random_walk')
WHITE_GM = ('white_noise', 'gauss_markov')


def warm_record(seed=11):
    """Return samples (SI) with a settling bias at the start, temperatures 20 -> 30 deg C."""
    rng = np.random.default_rng(seed)
    white = np.array([3e-4] * 3 + [2e-3] * 3) * math.sqrt(RATE)   # N sqrt(f), per sample
    walk = np.array([2e-6] * 3 + [2e-5] * 3) / math.sqrt(RATE)     # K / sqrt(f), per sample
    t = np.arange(N) / RATE
    data = (rng.standard_normal((N, 6)) * white
            + np.cumsum(rng.standard_normal((N, 6)), axis=0) * walk
            + np.array([3e-3] * 3 + [3e-2] * 3) * np.exp(-t / 300.0)[:, None])
    data[:, 5] += 9.80665
    temp_t = np.arange(0.0, N / RATE, 1.0)
    celsius = 20.0 + 10.0 * (1.0 - np.exp(-temp_t / 300.0))
    return Samples(t=T0 + t, data=data, source='warm',
                   temperature=Temperatures('/imu/temperature', T0 + temp_t, celsius))


@pytest.fixture(scope='module')
def record():
    """Every part asked for: denoised, dynamic (default window), two overbound models."""
    options = RecordOptions(analysis=AnalysisOptions(), dynamic_window_s=0.0, denoise=True,
                            overbound=OverboundRequest(((WHITE_WALK, 'axis'),
                                                        (WHITE_GM, 'sensor'))))
    steps = []
    rec = analyze_record(warm_record(), options, steps.append)
    rec.steps = steps
    return rec


def test_the_analysed_stamps_and_samples_agree(record):
    """Analysis.t and Analysis.data are the same rows: the record after the warm-up cut."""
    analysis = record.analysis
    samples = record.samples
    assert 600.0 < analysis.warmup_s < 1800.0           # 3 x 300 s, within a factor 2
    cut = samples.n - analysis.n_samples
    assert cut == round(analysis.warmup_s * RATE)
    assert analysis.t.shape == (analysis.n_samples,) and analysis.data.shape[0] == analysis.t.size
    assert np.array_equal(analysis.t, samples.t[cut:])
    assert np.array_equal(analysis.data, samples.data[cut:])


def test_every_part_is_named_and_computed_once(record):
    assert isinstance(record, RecordAnalysis)
    assert record.steps == ['Allan deviation and fit', 'denoising', 'dynamic Allan deviation']
    assert set(record.sensor.axes) == set(AXES)          # measured with the estimate
    assert record.sensor is record.analysis.sensor
    assert set(record.advice.axes) == set(AXES) and record.advice.targets
    # denoised: the analysed rows, denoised, with their own stamps
    den = record.denoised
    assert np.array_equal(den.samples.t, record.analysis.t)
    assert den.samples.data.shape == record.analysis.data.shape
    assert den.analysis.source == 'warm (denoised)'
    assert den.samples.temperature is None and record.samples.temperature is not None
    # dynamic: times from the record's first sample; the windows start after the warm-up
    dyn = record.dynamic
    assert dyn.analysed_from_s == record.analysis.warmup_s
    assert dyn.result.t[0] > record.analysis.warmup_s + dyn.result.window_s / 2 - 1e-9


def test_temperature_part_from_the_readings_delivered_with_the_samples(record):
    part = record.temperature
    assert part.topic == '/imu/temperature' and set(part.slopes) == set(AXES)
    assert 20.0 <= part.range_c[0] < part.range_c[1] <= 30.0
    assert part.changes, 'a 10 deg C move was not found'
    warm = [c for c in part.coincidences if c.event == 'warmup']
    assert len(warm) == 1 and warm[0].t_s == record.analysis.warmup_s
    assert warm[0].temperature_change == 0               # the move starts with the record


def test_overbound_values_of_each_requested_model(record):
    """One fit per axis (WHITE_WALK), one per sensor envelope (WHITE_GM); nothing else."""
    values = record.overbound
    per_axis = {(a, WHITE_WALK) for a in AXES}
    envelopes = {(tuple(AXES[:3]), WHITE_GM), (tuple(AXES[3:]), WHITE_GM)}
    assert set(values.fits) == per_axis | envelopes
    for axes, shapes in per_axis | envelopes:
        fit = values.get(axes, shapes)
        assert fit.value('white_noise') > 0 and fit.horizon_s == record.analysis.result.tau[-1]
    assert values.get('gyro_x', WHITE_GM) is None       # not asked for


def test_an_overbound_that_cannot_be_made_is_kept_as_its_reason():
    """A horizon beyond the measured taus: stored, raised only where it is asked for."""
    options = RecordOptions(overbound=OverboundRequest(((WHITE_WALK, 'axis'),), 1e9))
    samples = warm_record(seed=3)
    rec = analyze_record(Samples(t=samples.t[:20000], data=samples.data[:20000]), options)
    assert all(isinstance(v, HorizonError) for v in rec.overbound.fits.values())
    with pytest.raises(ValueError, match='horizon'):
        rec.overbound.get('gyro_x', WHITE_WALK)
