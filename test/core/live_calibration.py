"""
Calibration at every record length, measured: what ``analyze`` and the allan node report.

Records of 10 s to 24 h of known truth from the independent generator (independent_imu.py,
which shares no code with the package), with and without a device's processing (a moving
average at 1 kHz decimated to 100 Hz, LSB rounding, a line), are analysed two ways:

* offline: each length a record of its own, through ``analyze``'s pipeline
  (:func:`imu_allan.core.analysis.analyze_samples`, its sensor measurement included);
* online: one stream per six axes fed to the allan node's pipeline
  (:class:`imu_allan.core.live.online.OnlineAllan`) block by block, fitted as it grows at
  every checkpoint length (the node's estimate at that age).

Per length: the share of axes that report a term the generator lacked (a sinusoid counts
where the device had no line, a Gauss-Markov always); for every reported term, how often its
68.3 % and 95 % intervals hold the truth, a reported term the generator lacks counting as a
miss of both; for every true term not reported, how often its 95 % upper limit holds the
truth.  ``python test/core/live_calibration.py [axes per cell] [--online] [--lengths ...]``
prints the table of docs/method.md (section 11); test_live_calibration.py runs the fast part.

The units: physical IMUs with their terms fixed, each coefficient drawn per axis within a
factor 0.7-1.4 of the unit's, so that a record of a given length resolves some terms and not
others, as a real one does (the thesis's 3DM-GX3-25 resolves its bias instability only after
about 10 minutes).
"""

from concurrent.futures import ProcessPoolExecutor
import math
import os
import sys
import time

if __package__ in (None, ''):  # run as a script: the test folder's modules on the path
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from core.independent_imu import Device, IndependentAxis  # noqa: E402
from imu_allan.core.allan.edf import CI_LEVEL  # noqa: E402
from imu_allan.core.analysis import analyze_samples  # noqa: E402
from imu_allan.core.live.online import OnlineAllan  # noqa: E402
from imu_allan.core.units import AXES  # noqa: E402
from imu_allan.formats.samples import Samples  # noqa: E402
import numpy as np  # noqa: E402

RATE = 100.0
#: The record lengths of the table, s.
LENGTHS = (10.0, 30.0, 60.0, 300.0, 1800.0, 7200.0, 86400.0)
#: The units: nominal coefficients (SI, continuous-time), drawn per axis within DRAW.
UNITS = {
    # the thesis's 3DM-GX3-25 (its tables 4.1, 4.2): gyro and accelerometer
    'gx3_gyro': {'white_noise': 5.76e-4, 'bias_instability': 1.5e-4},
    'gx3_accel': {'white_noise': 8.33e-4, 'bias_instability': 6.4e-4},
    # an ADIS16405-like gyro (the real runs' N and B) with a random walk reaching the
    # flicker floor at about 2000 s
    'adis_gyro': {'white_noise': 7.1e-4, 'bias_instability': 1.45e-4,
                  'rate_random_walk': 3.7e-6},
    # a consumer MEMS gyro: low white noise, weak flicker, a random walk from ~2000 s
    'mems_gyro': {'white_noise': 2.44e-4, 'bias_instability': 4.0e-5,
                  'rate_random_walk': 1.0e-6},
    # a tactical accelerometer with a thermal ramp over the flicker floor from ~2000 s
    'ramp_accel': {'white_noise': 1.0e-4, 'bias_instability': 2.0e-5, 'rate_ramp': 1.0e-8},
    # white noise and a random walk, no flicker (crossing at ~170 s)
    'walk_gyro': {'white_noise': 5.0e-4, 'rate_random_walk': 5.0e-6},
    # angle quantization over white noise up to ~5 samples, then flicker
    'quant_gyro': {'quantization': 1.6e-5, 'white_noise': 5.76e-4, 'bias_instability': 1.5e-4},
    # white noise alone
    'white': {'white_noise': 5.0e-4},
}
DRAW = (0.7, 1.4)
#: Units made without a device: angle quantization is an integrating sensor's (a delta-angle
#: output), not what a rate sensor's window and LSB give (the rate LSB is white noise,
#: docs/method.md section 9), and the fit leaves it out beside a filter by design.
NO_DEVICE = {'quant_gyro'}
#: Device processing drawn per axis: taps of a moving average at 10x the output rate, the LSB
#: in output noise sigmas (log-uniform), the chance of a line, its input frequency (Hz, it
#: aliases) and its output amplitude in noise sigmas (log-uniform).
TAPS = (1, 32)
LSB_SIGMAS = (0.1, 1.4)
LINE_CHANCE = 0.5
LINE_HZ = (20.0, 450.0)
LINE_SIGMAS = (0.1, 0.5)
#: Reported terms that are the sensor's, not noise, when the device has a line.
LINE_TERMS = {'sinusoid'}


def _log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def draw_axis(unit, rng, device, duration_s):
    """Return an :class:`IndependentAxis` of ``unit`` (coefficients drawn), with a device."""
    truth = {t: v * _log_uniform(rng, *DRAW) for t, v in UNITS[unit].items()}
    dev = None
    if device:
        line = None
        if rng.uniform() < LINE_CHANCE:
            line = (rng.uniform(*LINE_HZ), _log_uniform(rng, *LINE_SIGMAS))
        dev = Device(10, int(rng.integers(TAPS[0], TAPS[1] + 1)),
                     _log_uniform(rng, *LSB_SIGMAS), line)
    return IndependentAxis(truth, RATE, duration_s, rng, dev)


def truth_of(axis):
    """Return the terms an analysis should find (SI): the white density the output carries."""
    truth = {t: v for t, v in axis.truth.items() if t != 'gauss_markov'}
    if 'white_noise' in truth:
        truth['white_noise'] = axis.white_truth()
    return truth


def score(fitted, name, axis):
    """One axis's outcome: spurious terms, per-term coverage, upper-limit coverage."""
    truth = truth_of(axis)
    allowed = set(truth) | (LINE_TERMS if axis.device.line is not None else set())
    reported = set(fitted.model.terms.get(name, {}))
    row = {'spurious': sorted(reported - allowed), 'cover': {}, 'limit': {}}
    for term in reported - (LINE_TERMS & allowed):
        if term not in truth:
            row['cover'][term] = (False, False)
            continue
        row['cover'][term] = tuple(_inside(fitted.interval(name, term, level=lv), truth[term])
                                   for lv in (CI_LEVEL, 0.95))
    for term, value in truth.items():
        if term not in reported:
            limit = fitted.upper_limit(name, term)
            row['limit'][term] = bool(value <= limit) if math.isfinite(limit) else None
    return row


def _inside(interval, value):
    lo, hi = interval
    return bool(lo <= value <= hi)


def offline_group(args):
    """Six axes of one unit as one record of ``length`` s, analysed offline; rows."""
    unit, device, length, seed = args
    rng = np.random.default_rng(seed)
    axes = [draw_axis(unit, rng, device, length) for _ in AXES]
    n = int(round(length * RATE))
    data = np.column_stack([a.take(n) for a in axes])
    samples = Samples(np.arange(n) / RATE, data, AXES, f'{unit} seed {seed}')
    fitted = analyze_samples(samples).fit
    return [(unit, device, length, score(fitted, name, a)) for name, a in zip(AXES, axes)]


def online_group(args):
    """Six axes of one unit streamed to the node's pipeline, fitted at each checkpoint."""
    unit, device, lengths, seed = args
    rng = np.random.default_rng(seed)
    total = max(lengths)
    axes = [draw_axis(unit, rng, device, total) for _ in AXES]
    pipeline = OnlineAllan(RATE, AXES)
    rows, made = [], 0
    block = int(10 * RATE)
    for length in sorted(lengths):
        n = int(round(length * RATE))
        while made < n:
            k = min(block, n - made)
            data = np.column_stack([a.take(k) for a in axes])
            pipeline.feed((made + np.arange(k)) / RATE, data)
            made += k
        fitted = pipeline.fit(pipeline.result())
        if fitted is not None:
            rows += [(unit, device, length, score(fitted, name, a))
                     for name, a in zip(AXES, axes)]
    return rows


def run(lengths=LENGTHS, groups=2, seed=1, online=False, workers=None, units=UNITS,
        log=None):
    """Return the rows of ``groups`` six-axis records per unit and device setting."""
    jobs = []
    for u, unit in enumerate(units):
        for device in (False,) if unit in NO_DEVICE else (False, True):
            for g in range(groups):
                s = seed + 1000 * u + 100 * device + g
                if online:
                    jobs.append((online_group, (unit, device, lengths, s)))
                else:
                    jobs += [(offline_group, (unit, device, length, s + 7 * k))
                             for k, length in enumerate(lengths)]
    rows = []
    workers = workers or min(2, os.cpu_count() or 1)
    t0 = time.time()
    if workers == 1:
        for fn, job in jobs:
            rows += fn(job)
    else:
        with ProcessPoolExecutor(workers) as pool:
            futures = [pool.submit(fn, job) for fn, job in jobs]
            for k, f in enumerate(futures):
                rows += f.result()
                if log:
                    log(f'{k + 1}/{len(jobs)} records, {time.time() - t0:.0f} s')
    return rows


def summary(rows):
    """Per length: axes, spurious share, coverage per term, upper-limit coverage."""
    out = {}
    for _unit, _device, length, row in rows:
        s = out.setdefault(length, {'axes': 0, 'spurious': 0, 'cover': {}, 'limit': {}})
        s['axes'] += 1
        s['spurious'] += bool(row['spurious'])
        for term, flags in row['cover'].items():
            s['cover'].setdefault(term, []).append(flags)
        for term, ok in row['limit'].items():
            if ok is not None:
                s['limit'].setdefault(term, []).append(ok)
    for s in out.values():
        flags = [f for fs in s['cover'].values() for f in fs]
        s['pooled'] = (len(flags), *np.mean(np.array(flags, float), axis=0)) if flags else (0,)
        s['cover'] = {t: (len(f), *np.mean(np.array(f, float), axis=0))
                      for t, f in s['cover'].items()}
        s['limit'] = {t: (len(f), float(np.mean(f))) for t, f in s['limit'].items()}
    return dict(sorted(out.items()))


SHORT = {'quantization': 'Q', 'white_noise': 'N', 'bias_instability': 'B',
         'rate_random_walk': 'K', 'rate_ramp': 'R', 'gauss_markov': 'GM', 'sinusoid': 'A'}


def table(rows):
    """Markdown table of :func:`summary`."""
    lines = ['| length | axes | spurious-term axes | reported terms: 68.3 % / 95 % hold the '
             'truth (cases) | pooled | true terms not reported: 95 % upper limit holds (cases) |',
             '|---|---|---|---|---|---|']
    for length, s in summary(rows).items():
        cover = ', '.join(f'{SHORT[t]} {100 * c68:.0f} / {100 * c95:.0f} ({n})'
                          for t, (n, c68, c95) in sorted(s['cover'].items(),
                                                         key=lambda x: SHORT[x[0]]))
        pooled = (f'{100 * s["pooled"][1]:.1f} / {100 * s["pooled"][2]:.1f} '
                  f'({s["pooled"][0]})' if s['pooled'][0] else '-')
        limit = ', '.join(f'{SHORT[t]} {100 * c:.0f} ({n})' for t, (n, c) in
                          sorted(s['limit'].items(), key=lambda x: SHORT[x[0]]))
        lines.append(f'| {_length(length)} | {s["axes"]} | '
                     f'{100 * s["spurious"] / s["axes"]:.1f} % | {cover} | {pooled} | {limit} |')
    return '\n'.join(lines)


def _length(seconds):
    return (f'{seconds / 3600:g} h' if seconds >= 3600 else
            f'{seconds / 60:g} min' if seconds >= 60 else f'{seconds:g} s')


if __name__ == '__main__':
    args = [a for a in sys.argv[1:] if not a.startswith('--')]
    n_groups = int(args[0]) if args else 2
    chosen = LENGTHS
    if '--lengths' in sys.argv:
        chosen = tuple(float(x) for x in sys.argv[sys.argv.index('--lengths') + 1].split(','))
    t_start = time.time()
    result = run(chosen, n_groups, online='--online' in sys.argv,
                 log=lambda text: print(text, file=sys.stderr, flush=True))
    print(table(result))
    spurious = [(u, d, length, r['spurious']) for u, d, length, r in result if r['spurious']]
    print('\nspurious:', spurious)
    print(f'\n{time.time() - t_start:.0f} s', file=sys.stderr)
