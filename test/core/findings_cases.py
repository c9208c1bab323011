"""
Simulator defects (and non-defects) for the discrepancy findings: cases, runs and rates.

Each :class:`Case` pairs a simulator's noise as implemented with the same simulator as its
parameters are documented (the *correct* implementation, :mod:`simulator_pairs`), states the
intended model the way a user would write it (a model file: continuous-time SI), and says which
finding the defect must give and its true factor.  ``run_case`` runs one seed of a case
through :func:`imu_allan.core.discrepancy.find_discrepancies`; ``suite`` runs many.

The sizes (minutes, runs, rates) are the smallest that resolve each effect; the full-size
measurement (``python test/core/findings_cases.py [SEEDS]``) prints the table of
docs/discrepancy.md.
"""

from dataclasses import dataclass, field
import math

from imu_allan.core.discrepancy import find_discrepancies, Recording
from imu_allan.core.model import NoiseModel
import numpy as np

try:  # as a test module (test/ on the path) or as a script from test/core
    from core import simulator_pairs as sp
except ImportError:
    import simulator_pairs as sp

RATES = (100.0, 250.0, 1000.0)
GZ = sp.GZ_TUTORIAL
PX4 = sp.PX4_IRIS


@dataclass
class Case:
    """
    One defect: its generators, the stated model, what must be found.

    ``run(axes, n, rate, seed, correct)`` gives samples; ``model(axes, rate)`` the stated
    NoiseModel (per rate: a per-sample quantity read at each rate); ``cls``/``term`` the
    expected finding (None: a non-defect, nothing may be found); ``factor`` the true factor
    (at 1 Hz when ``exponent`` is set); ``covariance(axes, rate, correct)`` the Imu covariance
    diagonals the messages carry (metadata cases); ``correct_model(axes, rate)`` the model of
    the correct side when the defect is in the stated model, not in the simulator (the data
    are then the same on both sides).
    """

    name: str
    source: str
    run: object
    model: object
    cls: str = None
    term: str = None
    factor: float = None
    exponent: float = None
    axes: tuple = ('gyro_x',)
    rates: tuple = RATES
    runs: int = 1
    minutes: float = 20.0
    covariance: object = None
    correct_model: object = None
    extra: dict = field(default_factory=dict)


def _white(value):
    return {'white_noise': {'value': value}}


def _gm(sigma, tau_c):
    return {'gauss_markov': {'sigma': sigma, 'tau_c': tau_c}}


def _px4_model(axes, rate, turn_on=True):
    terms, turn = {}, {}
    for a in axes:
        p = PX4[sp.sensor(a)]
        terms[a] = {**_white(p['density']),
                    **_gm(p['random_walk'] * math.sqrt(p['tau'] / 2.0), p['tau'])}
        if turn_on:
            turn[a] = {'mean': 0.0, 'sigma': p['turn_on']}
    return NoiseModel(terms, turn_on_bias=turn)


def _gz_only(keys):
    return {s: {k: v for k, v in p.items() if k in keys} for s, p in GZ.items()}


GZ_WHITE = _gz_only(('stddev',))
GZ_DYNAMIC = _gz_only(('stddev', 'dynamic_bias_stddev', 'dynamic_bias_correlation_time'))
GZ_SIGN = {'accel': {'stddev': GZ['accel']['stddev'], 'bias_mean': GZ['accel']['bias_mean'],
                     'bias_stddev': GZ['accel']['bias_stddev']}}
HECTOR = {'drift': 0.01, 'frequency': 1.0 / 3600.0, 'white': 1e-4}
#: A "bounded" bias whose correlation time lies inside a half-hour record, for the
#: wrong-process case (no real default is short enough: PX4's 300 s needs 3 h records).
SHORT_GM = {'density': 2e-4, 'random_walk': 4e-5, 'tau': 20.0, 'turn_on': 0.0}


def _gz_white_model(axes, rate):
    """Return the gz white noise as it is at ``rate`` (per sample): isolates the others."""
    return {a: _white(GZ[sp.sensor(a)]['stddev'] / math.sqrt(rate)) for a in axes}


CASES = [
    Case('gz_stddev_per_sample', 'gz-sensors GaussianNoiseModel.cc; gazebo-classic#2670',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, GZ_WHITE, per_sample=not correct),
         lambda axes, rate: NoiseModel({a: _white(GZ[sp.sensor(a)]['stddev']) for a in axes}),
         'white_scale', 'white_noise', 1.0, -0.5, minutes=5.0),
    Case('gz_dynamic_bias_driving', 'gz-sensors GaussianNoiseModel.cc; gz-sensors#616',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, GZ_DYNAMIC, driving=not correct),
         lambda axes, rate: NoiseModel({a: {**_gz_white_model(axes, rate)[a], **_gm(
             GZ[sp.sensor(a)]['dynamic_bias_stddev'],
             GZ[sp.sensor(a)]['dynamic_bias_correlation_time'])} for a in axes}),
         'bias_scale', 'gauss_markov', math.sqrt(400.0 / 2.0), minutes=60.0,
         rates=(100.0, 250.0)),
    Case('hector_drift_dt', 'hector_gazebo sensor_model.h',
         lambda axes, n, rate, seed, correct: np.column_stack([sp.hector_axis(
             np.random.default_rng([*seed, k]), n, rate, HECTOR['drift'], HECTOR['frequency'],
             HECTOR['white'], sqrt_dt=correct) for k, _ in enumerate(axes)]),
         lambda axes, rate: NoiseModel({a: {**_white(HECTOR['white']), **_gm(
             HECTOR['drift'], 1.0 / HECTOR['frequency'])} for a in axes}),
         'bias_scale', 'gauss_markov', 1.0, -0.5, minutes=30.0),
    Case('px4_covariance_density', 'PX4-SITL_gazebo-classic gazebo_imu_plugin.cpp',
         lambda axes, n, rate, seed, correct: sp.px4_run(axes, n, rate, seed),
         lambda axes, rate: _px4_model(axes, rate, turn_on=False),
         'metadata', 'white_noise', 1.0, -1.0, minutes=5.0,
         covariance=lambda axes, rate, correct: sp.px4_covariance(axes, rate,
                                                                  per_sample=correct)),
    Case('gz_turn_on_sign', 'gz-sensors GaussianNoiseModel.cc Load; gz-sensors#360',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, GZ_SIGN, random_sign=not correct),
         lambda axes, rate: NoiseModel({a: _white(GZ['accel']['stddev'] / math.sqrt(rate))
                                        for a in axes},
                                       turn_on_bias={a: {'mean': GZ['accel']['bias_mean'],
                                                         'sigma': GZ['accel']['bias_stddev']}
                                                     for a in axes}),
         'run_to_run', 'turn_on_bias', 0.0, axes=('accel_x',), rates=(250.0,), runs=10,
         minutes=1.0, extra={'kind': 'bimodal'}),
    Case('px4_tau_from_accel', 'PX4 gyroscope bias with the accelerometer correlation time',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, turn_on=False, tau_of=None if correct else {'gyro': 300.0}),
         lambda axes, rate: _px4_model(axes, rate, turn_on=False),
         'time_constant', 'gauss_markov', 300.0 / 1000.0, minutes=360.0, rates=(100.0,)),
    Case('walk_for_bounded_bias', 'a Gauss-Markov bias integrated without its decay',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, config={'gyro': SHORT_GM, 'accel': SHORT_GM},
             turn_on=False, walk=not correct),
         lambda axes, rate: NoiseModel({a: {**_white(SHORT_GM['density']), **_gm(
             SHORT_GM['random_walk'] * math.sqrt(SHORT_GM['tau'] / 2.0), SHORT_GM['tau'])}
             for a in axes}),
         'wrong_process', 'gauss_markov', 1.0, rates=(100.0, 250.0), minutes=30.0),
    Case('bounded_for_walk', 'PX4 RandomWalk read as a random walk: the plugin bounds it',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, config={'gyro': SHORT_GM, 'accel': SHORT_GM},
             turn_on=False, walk=correct),
         lambda axes, rate: NoiseModel({a: {**_white(SHORT_GM['density']),
                                            'rate_random_walk': {
                                                'value': SHORT_GM['random_walk']}}
                                        for a in axes}),
         'wrong_process', 'rate_random_walk', 1.0, rates=(100.0, 250.0), minutes=30.0),
    Case('dynamic_bias_ignored', 'gz-sensors before the dynamic bias (ApplyImpl without dt)',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, GZ_DYNAMIC, dynamic=correct),
         lambda axes, rate: NoiseModel({a: {**_gz_white_model(axes, rate)[a], **_gm(
             GZ[sp.sensor(a)]['dynamic_bias_stddev']
             * math.sqrt(GZ[sp.sensor(a)]['dynamic_bias_correlation_time'] / 2.0),
             GZ[sp.sensor(a)]['dynamic_bias_correlation_time'])} for a in axes}),
         'term_absent', 'gauss_markov', 0.0, minutes=30.0, rates=(100.0, 250.0)),
    Case('biased_drive', 'a bias drive with a non-zero mean (half its sd per step)',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, turn_on=False, drive_mean=0.0 if correct else 0.5),
         lambda axes, rate: _px4_model(axes, rate, turn_on=False),
         'biased_drive', 'gauss_markov', 0.5, axes=('gyro_x', 'gyro_y'), rates=(250.0,),
         runs=10, minutes=1.0),
    Case('gz_turn_on_decays', 'gz-sensors: the turn-on bias starts the dynamic process',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, {'gyro': GZ['gyro']}, random_sign=False,
             turn_on_in_process=not correct),
         lambda axes, rate: NoiseModel(
             {a: {**_gz_white_model(axes, rate)[a], **_gm(
                 GZ['gyro']['dynamic_bias_stddev'] * math.sqrt(200.0), 400.0)} for a in axes},
             turn_on_bias={a: {'mean': GZ['gyro']['bias_mean'],
                               'sigma': GZ['gyro']['bias_stddev']} for a in axes}),
         'run_to_run', 'turn_on_bias', math.exp(-0.9 * 5.0 * 60.0 / 400.0), rates=(250.0,),
         runs=10, minutes=5.0, extra={'kind': 'decay'}),
    Case('turn_on_bias_zeroed', 'PX4-gazebo-models: no TurnOnBiasSigma in gz',
         lambda axes, n, rate, seed, correct: sp.px4_run(axes, n, rate, seed, turn_on=correct),
         lambda axes, rate: _px4_model(axes, rate),
         'run_to_run', 'turn_on_bias', 0.0, rates=(250.0,), runs=10, minutes=1.0,
         extra={'kind': 'spread'}),
    Case('rms_in_density_field', 'a per-sample RMS (at 200 Hz) typed into NoiseDensity',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, turn_on=False,
             config={s: dict(p, density=p['density'] * (1.0 if correct else math.sqrt(200.0)))
                     for s, p in PX4.items()}),
         lambda axes, rate: _px4_model(axes, rate, turn_on=False),
         'white_scale', 'white_noise', math.sqrt(200.0), minutes=5.0),
    Case('px4_uniform_drive', 'a uniform draw in [0, 1) for the bias drive (PX4 addNoise)',
         lambda axes, n, rate, seed, correct: sp.px4_run(
             axes, n, rate, seed, turn_on=False, uniform_drive=not correct),
         lambda axes, rate: _px4_model(axes, rate, turn_on=False),
         'biased_drive', 'gauss_markov', 0.5, axes=('gyro_x', 'gyro_y', 'gyro_z'),
         rates=(250.0,), minutes=5.0),
    Case('gz_uniform_drive', 'a uniform draw in [0, 1) for the dynamic bias (gz-sensors)',
         lambda axes, n, rate, seed, correct: sp.gz_run(
             axes, n, rate, seed, GZ_DYNAMIC, uniform_drive=not correct),
         lambda axes, rate: NoiseModel({a: {**_gz_white_model(axes, rate)[a], **_gm(
             GZ[sp.sensor(a)]['dynamic_bias_stddev']
             * math.sqrt(GZ[sp.sensor(a)]['dynamic_bias_correlation_time'] / 2.0),
             GZ[sp.sensor(a)]['dynamic_bias_correlation_time'])} for a in axes}),
         'biased_drive', 'gauss_markov', 0.5, axes=('accel_x', 'accel_y', 'accel_z'),
         rates=(100.0,), runs=2, minutes=10.0),
    Case('rms_density_bias_zeroed', 'PX4 block with per-sample RMS (200 Hz) densities and '
         'RandomWalk 0, against the sensor it should simulate',
         lambda axes, n, rate, seed, correct: sp.px4_run(axes, n, rate, seed, turn_on=False),
         lambda axes, rate: NoiseModel({a: {**_white(PX4[sp.sensor(a)]['density']
                                                     * math.sqrt(200.0)),
                                            **_gm(0.0, PX4[sp.sensor(a)]['tau'])}
                                        for a in axes}),
         'zeroed_term', 'gauss_markov', 1.0 / math.sqrt(200.0), axes=('gyro_x', 'accel_x'),
         rates=(100.0, 250.0), minutes=10.0, correct_model=lambda axes, rate: _px4_model(
             axes, rate, turn_on=False)),
    Case('white_one_percent', 'non-defect: a white noise stated 1 % high (gz stddev 1.01 x)',
         lambda axes, n, rate, seed, correct: sp.gz_run(axes, n, rate, seed, GZ_WHITE,
                                                        per_sample=False),
         lambda axes, rate: NoiseModel({a: _white(1.01 * GZ[sp.sensor(a)]['stddev'])
                                        for a in axes}),
         axes=('gyro_x', 'accel_x'), rates=(250.0, 1000.0), runs=2, minutes=10.0,
         correct_model=lambda axes, rate: NoiseModel({a: _white(GZ[sp.sensor(a)]['stddev'])
                                                      for a in axes})),
    Case('px4_as_coded', 'non-defect: PX4 RandomWalk is a driving density, as documented',
         lambda axes, n, rate, seed, correct: sp.px4_run(axes, n, rate, seed),
         lambda axes, rate: _px4_model(axes, rate), axes=('gyro_x', 'accel_x'), minutes=5.0),
    Case('expm1_vs_exp_minus_one', 'non-defect: gz-sensors#360 (expm1 for exp - 1)',
         lambda axes, n, rate, seed, correct: sp.gz_run(axes, n, rate, seed, GZ_DYNAMIC),
         lambda axes, rate: NoiseModel({a: {**_gz_white_model(axes, rate)[a], **_gm(
             GZ[sp.sensor(a)]['dynamic_bias_stddev']
             * math.sqrt(GZ[sp.sensor(a)]['dynamic_bias_correlation_time'] / 2.0),
             GZ[sp.sensor(a)]['dynamic_bias_correlation_time'])} for a in axes}),
         minutes=30.0, rates=(100.0, 250.0)),
]
BY_NAME = {c.name: c for c in CASES}


def recordings(case, seed, correct, scale=1.0):
    """Return the case's runs at every rate and the stated model of each."""
    recs, models = [], []
    for i, rate in enumerate(case.rates):
        n = int(round(case.minutes * scale * 60.0 * rate))
        for k in range(case.runs):
            run_seed = [seed, i, k, 1 + int(correct)]
            data = case.run(case.axes, n, rate, run_seed, correct)
            cov = case.covariance(case.axes, rate, correct) if case.covariance else None
            recs.append(Recording(data, rate, case.axes, f'{case.name}:{rate:g}Hz#{k}', cov))
            stated = case.correct_model if correct and case.correct_model else case.model
            models.append(stated(case.axes, rate))
    return recs, models


def run_case(case, seed, correct=False, scale=1.0):
    """Run one seed of a case; returns the FindingsResult."""
    recs, models = recordings(case, seed, correct, scale)
    return find_discrepancies(recs, models)


def matching(case, result):
    """Return the findings of the expected class and term (and kind, for run_to_run)."""
    out = [f for f in result.findings if f.cls == case.cls and f.term == case.term]
    if 'kind' in case.extra:
        out = [f for f in out if f.evidence.get('kind') == case.extra['kind']]
    return out


def covers(case, finding, level='factor_ci95'):
    """Return True when the finding's interval holds the true factor (and exponent)."""
    ci = getattr(finding, level)
    if ci is None or not ci[0] <= case.factor <= ci[1]:
        return False
    if case.exponent is not None:
        if finding.rate_exponent_ci is None:
            return False
        half = (finding.rate_exponent_ci[1] - finding.rate_exponent_ci[0]) / 2.0
        z = 1.0 if level == 'factor_ci' else 1.959964
        return abs(finding.rate_exponent - case.exponent) <= z * half
    return True


def record(case, seed, scale=1.0):
    """Both implementations of one seed: what was named, covered and left consistent."""
    bad = run_case(case, seed, False, scale)
    good = run_case(case, seed, True, scale)
    hits = matching(case, bad) if case.cls else []
    return {'case': case.name, 'seed': seed, 'named': bool(hits) if case.cls else None,
            'covered68': all(covers(case, f, 'factor_ci') for f in hits) if hits else None,
            'covered95': all(covers(case, f) for f in hits) if hits else None,
            'found': [f.factor for f in hits],
            'exponent': [f.rate_exponent for f in hits],
            'defect_consistent': bad.consistent,
            'correct_consistent': good.consistent,
            'correct_findings': [(f.cls, f.axis, f.term) for f in good.findings],
            'defect_findings': [(f.cls, f.axis, f.term) for f in bad.findings],
            'within': [(f.cls, f.axis, f.factor, f.within_percent) for f in bad.within]}


def suite(cases=CASES, seeds=range(5), scale=1.0):
    """Return the records of every case and seed."""
    return [record(c, s, scale) for c in cases for s in seeds]


def summary(records):
    """Rates of the suite: named, covered, consistent on correct implementations."""
    defects = [r for r in records if r['named'] is not None]
    named = [r for r in defects if r['named']]
    return {'cases': len(defects), 'named': len(named) / max(len(defects), 1),
            'covered95': sum(r['covered95'] for r in named) / max(len(named), 1),
            'covered68': sum(r['covered68'] for r in named) / max(len(named), 1),
            'correct': len(records),
            'correct_consistent': sum(r['correct_consistent'] for r in records)
            / max(len(records), 1),
            'non_defect_consistent': [r['defect_consistent'] for r in records
                                      if r['named'] is None]}


def table(records):
    """Rows for docs/discrepancy.md: case, source, expected and found factor (median)."""
    rows = []
    for case in CASES:
        rs = [r for r in records if r['case'] == case.name]
        if not rs:
            continue
        found = [f for r in rs for f in r['found']]
        exps = [e for r in rs for e in r['exponent'] if e is not None]
        expected = ('consistent' if case.cls is None else
                    f'{case.cls} {case.factor:.3g}'
                    + (f' x (f/1 Hz)^{case.exponent:g}' if case.exponent is not None else ''))
        got = ('-' if not found else f'{np.median(found):.3g}'
               + (f' x (f/1 Hz)^{np.median(exps):.3f}' if exps else ''))
        named = (f'{sum(r["named"] for r in rs)}/{len(rs)}' if case.cls else
                 f'{sum(r["defect_consistent"] for r in rs)}/{len(rs)} consistent'
                 + (f' ({sum(bool(r["within"]) for r in rs)} significant, within the band)'
                    if any(r['within'] for r in rs) else ''))
        rows.append((case.name, case.source, expected, got, named,
                     f'{sum(r["correct_consistent"] for r in rs)}/{len(rs)}'))
    return rows


if __name__ == '__main__':  # the docs table: python test/core/findings_cases.py [SEEDS]
    import sys
    import time
    n_seeds = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    start = time.time()
    recs = suite(seeds=range(100, 100 + n_seeds))
    print(summary(recs))
    print('| case | source | expected | found (median) | named | correct consistent |')
    print('|---|---|---|---|---|---|')
    for row in table(recs):
        print('| ' + ' | '.join(row) + ' |')
    for r in recs:
        if r['named'] is False or r['covered95'] is False or not r['correct_consistent']:
            print('  miss', r)
    print(f'{time.time() - start:.0f} s')
