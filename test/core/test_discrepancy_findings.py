"""
Findings of the discrepancy workflow against the defects real simulators shipped (issues 31, 37).

The suite (:mod:`findings_cases`) runs every case of ``CASES`` with four seeds: each defect
through the simulator's code as implemented and as its parameters are documented (the correct
implementation), re-implemented in :mod:`simulator_pairs` from the simulators' sources,
independently of the package's simulator.  The issue's rates, asserted here:

* the defect's class (and term, and kind for run_to_run) is named on >= 90 % of the defect
  analyses (52; at most 5 misses) and on at least 3 of 4 seeds of every case;
* the true factor (and rate exponent) lies in the finding's 95 % interval on >= 90 % of the
  named ones; the 68.3 % interval's coverage is measured and must be at least 55 % (an
  honest 68.3 % interval covers 68 % +- 7 % on 52 cases; below 55 % the intervals would be
  too narrow by a factor of about 1.3);
* the correct implementations, and the non-defects, leave nothing on >= 95 % of their
  analyses (at most 3 of 72 with a finding; Bonferroni at 1 % per analysis makes about 0.7
  expected);
* a white noise stated 1 % off is never named, though its factor excludes 1 (the materiality
  band, :mod:`imu_allan.core.discrepancy.materiality`).

``python test/core/findings_cases.py 25`` measures the same with 25 seeds (docs/discrepancy.md).
The building blocks (pooling over rates, the run-to-run tests, the model file's turn-on bias,
the SDF reader's documented reading and its suggestions) are tested on their own below.
"""

import math

from core import simulator_pairs as sp
from core.findings_cases import BY_NAME, CASES, run_case, suite, summary
from imu_allan.core.discrepancy import find_discrepancies, Finding, Recording
from imu_allan.core.discrepancy.evidence import LogEstimate
from imu_allan.core.discrepancy.materiality import Materiality
from imu_allan.core.discrepancy.pooling import pool, z_critical
from imu_allan.core.model import ModelError, NoiseModel
from imu_allan.formats.gazebo_sdf import read_sim_model
import numpy as np
import pytest

SEEDS = range(4)


@pytest.fixture(scope='module')
def records():
    """Every case, four seeds, both implementations."""
    return suite(CASES, SEEDS)


def test_defects_are_named(records):
    stats = summary(records)
    assert stats['cases'] == sum(1 for c in CASES if c.cls) * len(SEEDS)
    assert stats['named'] >= 0.90, [r for r in records if r['named'] is False]
    for case in CASES:
        if case.cls:
            named = [r['named'] for r in records if r['case'] == case.name]
            assert sum(named) >= 3, (case.name, named)


def test_factors_hold_the_truth(records):
    stats = summary(records)
    assert stats['covered95'] >= 0.90, [r for r in records if r['covered95'] is False]
    assert stats['covered68'] >= 0.55


def test_correct_implementations_stay_silent(records):
    stats = summary(records)
    assert stats['correct'] == len(CASES) * len(SEEDS)
    assert stats['correct_consistent'] >= 0.95, \
        [(r['case'], r['correct_findings']) for r in records if not r['correct_consistent']]
    # the non-defects, run as the issue reports them, are silent as well
    assert sum(stats['non_defect_consistent']) >= len(stats['non_defect_consistent']) - 1


def test_pooling_finds_a_rate_exponent():
    """Fit ln factor = a + p ln f on three rates; one rate gives a pooled factor only."""
    rates = (100.0, 250.0, 1000.0)
    noise = (0.01, -0.01, 0.005)
    est = [LogEstimate(-0.5 * math.log(r) + e, 0.01, r) for r, e in zip(rates, noise)]
    p = pool(est, z_critical(0.01, 10))
    assert p.scaled and abs(p.exponent + 0.5) < 3 * p.exponent_se
    assert p.interval()[0] < 1.0 < p.interval()[1] or abs(p.log) < 3 * p.se
    assert p.at_rate(250.0) == pytest.approx(250.0 ** -0.5, rel=0.03)
    flat = pool([LogEstimate(0.2, 0.05, 100.0), LogEstimate(0.1, 0.05, 100.5)], 3.0)
    assert not flat.scaled and flat.exponent is None
    assert flat.factor() == pytest.approx(math.exp(0.15))
    assert flat.se == pytest.approx(0.05 / math.sqrt(2.0))


def test_model_file_turn_on_bias(tmp_path):
    """``turn_on_bias: {mean, sigma}`` per sensor or axis; bad values are one-line errors."""
    path = tmp_path / 'm.yaml'
    path.write_text('gyro:\n  white_noise: 1.0e-3\n  turn_on_bias: {mean: -0.01, sigma: 0.002}\n'
                    'axes:\n  accel_x:\n    turn_on_bias: {mean: 0.1, sigma: 0.0}\n')
    model = NoiseModel.from_yaml(path)
    assert model.turn_on_bias['gyro_y'] == {'mean': -0.01, 'sigma': 0.002}
    assert model.turn_on_bias['accel_x'] == {'mean': 0.1, 'sigma': 0.0}
    assert 'accel_x' not in model.terms  # a turn-on bias alone is not noise
    again = NoiseModel.from_dict(model.to_dict())
    assert again.turn_on_bias == model.turn_on_bias and again.terms == model.terms
    for bad, needle in (('{mean: 0.0}', 'needs mean, sigma'),
                        ('{mean: 0.0, sigma: -1.0}', 'sigma'),
                        ('[1, 2]', 'mapping')):
        path.write_text(f'gyro:\n  turn_on_bias: {bad}\n')
        with pytest.raises(ModelError, match=needle):
            NoiseModel.from_yaml(path)


def test_turn_on_bias_decisions_on_runs():
    """
    Run-to-run evidence alone: a random sign is bimodal, a missing spread is spread.

    White noise only; the stated turn-on bias is silent, a sign drawn at random is named
    bimodal, a missing spread is named spread with a factor about 0.  Ten runs of 1 min at
    100 Hz; white noise 1e-3 rad/s/sqrt(Hz); turn-on N(0.05, 0.005).
    """
    model = NoiseModel({'gyro_x': {'white_noise': {'value': 1e-3}}},
                       turn_on_bias={'gyro_x': {'mean': 0.05, 'sigma': 0.005}})
    rng = np.random.default_rng(5)

    def runs(draw):
        return [Recording((draw() + 1e-2 * rng.standard_normal(6000))[:, None], 100.0,
                          ('gyro_x',), f'run{k}') for k in range(10)]
    stated = find_discrepancies(runs(lambda: rng.normal(0.05, 0.005)), model)
    assert stated.consistent, [f.to_dict() for f in stated.findings]
    signs = find_discrepancies(runs(lambda: rng.choice([-1, 1]) * rng.normal(0.05, 0.005)),
                               model)
    kinds = [f.evidence['kind'] for f in signs.findings if f.cls == 'run_to_run']
    assert 'bimodal' in kinds
    fixed = find_discrepancies(runs(lambda: 0.05), model)
    spread = [f for f in fixed.findings if f.evidence.get('kind') == 'spread']
    assert spread and spread[0].factor_ci[0] <= 0.0 + 1e-12 < 0.2 < 1.0


def test_several_rates_need_the_same_axes_only_where_stated():
    """Axes the model states nothing for are noted, not compared."""
    model = NoiseModel({'gyro_x': {'white_noise': {'value': 1e-3}}})
    rng = np.random.default_rng(1)
    rec = Recording(1e-2 * rng.standard_normal((6000, 2)), 100.0, ('gyro_x', 'gyro_y'))
    result = find_discrepancies([rec], model)
    assert result.consistent
    assert any('gyro_y' in n for n in result.notes)
    assert result.to_dict()['findings'] == [] and result.to_dict()['consistent'] is True


def test_px4_metadata_case_names_the_density(records):
    """The PX4 covariance case: stated / measured = 1 x (f / 1 Hz)^-1 (exponent -1 +- 0.05)."""
    case = BY_NAME['px4_covariance_density']
    hits = [r for r in records if r['case'] == case.name and r['named']]
    assert hits and all(abs(e + 1.0) < 0.05 for r in hits for e in r['exponent'])


def test_generators_follow_their_sources():
    """
    The re-implemented simulators give what their code implies (checked on the samples).

    gz per-sample stddev: the sample std is stddev at any rate; PX4: the white part is
    NoiseDensity / sqrt(dt); hector's dt-stepped drift has the stationary std drift sqrt(dt).
    """
    n = 200000
    x = sp.gz_run(('gyro_x',), n, 1000.0, 1, config={'gyro': {'stddev': 0.01}})
    assert np.std(x) == pytest.approx(0.01, rel=0.01)  # per sample, not 0.01 sqrt(1000)
    y = sp.px4_run(('gyro_x',), n, 250.0, 2, config={'gyro': dict(
        sp.PX4_IRIS['gyro'], random_walk=0.0, turn_on=0.0)})
    assert np.std(y) == pytest.approx(sp.PX4_IRIS['gyro']['density'] * math.sqrt(250.0),
                                      rel=0.01)
    # hector at 100 Hz, tau 20 s: the drift settles at drift sqrt(dt) = 0.1 drift
    rng = np.random.default_rng(3)
    h = sp.hector_axis(rng, 400000, 100.0, 1.0, 1.0 / 20.0, 0.0)
    assert np.std(h[20000:]) == pytest.approx(0.1, rel=0.15)


def test_one_percent_is_significant_and_never_named(records):
    """
    The white noise stated 1.01 x (two rates, two 10-min runs each): consistent within ~1 %.

    The factor's 95 % interval excludes 1 on most seeds (the case is one the old rule named),
    yet nothing is a finding; what is kept aside says the factor and how close it is.
    """
    rs = [r for r in records if r['case'] == 'white_one_percent']
    assert rs and all(r['defect_consistent'] and r['correct_consistent'] for r in rs)
    assert sum(bool(r['within']) for r in rs) >= 3
    for r in rs:
        for cls, _, factor, within in r['within']:
            assert cls == 'white_scale' and factor == pytest.approx(1 / 1.01, abs=0.005)
            assert 0.5 < within < 2.5


def _finding(cls, factor, ci95, exponent=None, **evidence):
    return Finding(cls, 'gyro_x', 'white_noise', factor, None, ci95, exponent, None, evidence)


def test_materiality_band():
    """Ratios outside the band are material, inside it are not; other classes always are."""
    band = Materiality()
    assert not band.material(_finding('white_scale', 1.01, [1.004, 1.016]))
    assert band.within_percent(_finding('white_scale', 1.01, [1.004, 1.016])) == \
        pytest.approx(1.6)
    assert band.material(_finding('white_scale', 1.3, [1.2, 1.4]))
    assert band.material(_finding('bias_scale', 0.7, [0.6, 0.8]))
    assert not band.material(_finding('metadata', 1.5, [1.45, 1.55]))  # a variance: band^2
    assert band.material(_finding('metadata', 1.6, [1.55, 1.65]))
    assert band.material(_finding('run_to_run', 0.9, [0.85, 0.95], kind='bimodal'))
    assert not band.material(_finding('run_to_run', 0.9, [0.85, 0.95], kind='spread'))
    assert band.material(_finding('biased_drive', 0.01, [0.005, 0.015]))
    # 1 at 1 Hz but f^-1/2: judged at the rates recorded
    scaled = _finding('white_scale', 1.0, [0.99, 1.01], -0.5, per_rate=[
        {'rate_hz': 100.0, 'factor': 0.1, 'factor_ci': [0.099, 0.101]}])
    assert band.material(scaled)
    assert Materiality(1.0, 1.0).material(_finding('white_scale', 1.01, [1.004, 1.016]))
    for lo, hi in ((1.1, 2.0), (0.0, 1.2), (0.8, 0.9)):
        with pytest.raises(ValueError, match='must hold 1'):
            Materiality(lo, hi)


def test_biased_drive_in_one_run_of_three_axes():
    """
    A uniform [0, 1) drive in one 5-min run of three gyro axes (PX4 addNoise).

    The sign test alone cannot reach the decision level with three slopes (p >= 0.25); the
    t test of the drive factors does.  The factor is the drive's mean over the stated step sd,
    0.5; nothing else is named (the drift's ramp and scale are the drive's, masked).
    """
    case = BY_NAME['px4_uniform_drive']
    result = run_case(case, 11)
    assert {f.cls for f in result.findings} == {'biased_drive'}
    for f in result.findings:
        assert f.evidence['p_sign'] >= 0.25 and f.evidence['p_value'] < 0.01 / result.n_tests
        assert f.factor_ci95[0] < 0.5 < f.factor_ci95[1]
        assert f.parameter == f'{f.axis}.gauss_markov'
        assert f.to_dict()['material'] is True


PX4_RMS = """<plugin name="rotors_gazebo_imu_plugin" filename="libgazebo_imu_plugin.so">
  <gyroscopeNoiseDensity>{g}</gyroscopeNoiseDensity>
  <gyroscopeRandomWalk>0</gyroscopeRandomWalk>
  <gyroscopeBiasCorrelationTime>1000.0</gyroscopeBiasCorrelationTime>
  <accelerometerNoiseDensity>{a}</accelerometerNoiseDensity>
  {accel_walk}
  <accelerometerBiasCorrelationTime>300.0</accelerometerBiasCorrelationTime>
</plugin>
"""


def test_rms_density_and_zeroed_walk_from_a_px4_block(tmp_path):
    """
    A PX4 block with per-sample RMS (at 200 Hz) densities and RandomWalk set to 0.

    Against the sensor it should simulate (PX4's iris noise, two 10-min records at 100 and
    250 Hz): the zeroed Gauss-Markov is named with the white factor 1 / sqrt(200) and the
    values to set in the plugin's own terms (RandomWalk the driving density: the true 3.88e-5
    and 0.006 within a factor 1.5, the spread of a 10-min walk's fit over six seeds being
    +-17 %; NoiseDensity within 3 %).  Left out (not written) the key is no zeroed term: the
    walk is then a missing term.
    """
    rms = {s: p['density'] * math.sqrt(200.0) for s, p in sp.PX4_IRIS.items()}
    axes = ('gyro_x', 'accel_x')
    recs = [Recording(sp.px4_run(axes, int(600 * rate), rate, [5, k], turn_on=False), rate,
                      axes) for k, rate in enumerate((100.0, 250.0))]
    for written in (True, False):
        path = tmp_path / f'px4_{written}.sdf'
        path.write_text(PX4_RMS.format(g=rms['gyro'], a=rms['accel'], accel_walk=(
            '<accelerometerRandomWalk>0</accelerometerRandomWalk>' if written else '')))
        sim = read_sim_model(path)
        models = [sim.intended_model(r.rate_hz)[0] for r in recs]
        result = find_discrepancies(recs, models)
        sim.suggest(result.findings, [r.rate_hz for r in recs])
        found = {f.axis: f for f in result.findings}
        gyro = found['gyro_x']
        assert gyro.cls == 'zeroed_term' and gyro.parameter == 'gyroscopeRandomWalk'
        assert gyro.factor_ci95[0] < 200 ** -0.5 < gyro.factor_ci95[1]
        assert 1 / 1.5 < gyro.suggested / sp.PX4_IRIS['gyro']['random_walk'] < 1.5
        assert gyro.evidence['also']['gyroscopeNoiseDensity'] == pytest.approx(
            sp.PX4_IRIS['gyro']['density'], rel=0.03)
        accel = [f for f in result.findings if f.axis == 'accel_x']
        if written:
            assert [f.cls for f in accel] == ['zeroed_term']
            assert 1 / 1.5 < accel[0].suggested / sp.PX4_IRIS['accel']['random_walk'] < 1.5
        else:
            assert sorted(f.cls for f in accel) == ['missing_term', 'white_scale']


def test_report_says_what_is_within_the_band(tmp_path):
    """The 1 % case's report: no finding, the kept-aside factor said in the console and page."""
    from imu_allan.report.discrepancy_report import (
        runs_report_dict,
        runs_summary_text,
        write_out_dir,
    )
    case = BY_NAME['white_one_percent']
    result = run_case(case, 0)
    report = runs_report_dict(result, case.model(case.axes, 250.0), ['a', 'b'])
    assert report['consistent'] and report['findings'] == []
    assert report['within_band'] and all(not f['material'] for f in report['within_band'])
    text = runs_summary_text(report)
    assert 'findings: none' in text and 'within the band that matters (0.8-1.25)' in text
    assert 'is consistent with the stated (within 1' in text
    write_out_dir(tmp_path / 'out', report, lambda folder: None)
    assert 'Within the band that matters' in (tmp_path / 'out' / 'report.html').read_text()
