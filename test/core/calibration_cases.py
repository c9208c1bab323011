"""
Calibration of the fit, measured: term selection, alternatives and interval coverage.

Many axes are simulated with known truth, analysed with the overlapping Allan variance and
fitted with automatic term selection (:func:`imu_allan.core.fit.fit_noise_model`).  Two
generators: the package's own (:func:`imu_allan.core.simulation.simulate.simulate_axis`) and an
independent one written here from the textbook definitions, sharing no code with the package:

* white noise N: per-sample std N sqrt(fs);
* quantization Q: white phase noise of std Q, differenced and divided by tau0;
* bias instability B: 1/f noise by shaping the FFT of white noise with B sqrt(fs / (2 pi f))
  (two-sided PSD B^2 / (2 pi f)), generated over 4x the record and cut, so the longest
  averaging times have their low-frequency power;
* rate random walk K: cumulative sum of steps of std K sqrt(tau0);
* rate ramp R: R t.

Scenarios: N B K, N B, N K, Q N B, N B R.  The parameters are drawn per axis (log-uniform)
so that every true term dominates a visible part of the curve: the crossing averaging times
are drawn within the measured span (see :data:`CROSSINGS`).

For every axis: is the selected term set the true one; is the true one selected or among the
alternatives; and per true term (when selected), does its 68.3 % / 95 % interval hold the
truth.  ``python test/core/calibration_cases.py [axes per cell] [--hadamard]`` prints the full
table of docs/method.md (``--hadamard``: with the Hadamard check of
:mod:`imu_allan.core.fit.hadamard_check`); ``... 48 --realistic`` the realistic tables of its
section 10 (a third generator, :func:`realistic_axis`, with the sensor measured as ``analyze``
does); test_calibration.py runs a smaller batch and checks the goals.
"""

import math
import sys
import time

from imu_allan.core.allan.edf import CI_LEVEL
from imu_allan.core.allan.estimate import AllanResult, avar_fast, tau_grid
from imu_allan.core.deviations import deviation
from imu_allan.core.fit import fit_noise_model, Processing
from imu_allan.core.simulation.simulate import simulate_axis
from imu_allan.core.units import AXES
import numpy as np
import scipy.fft
import scipy.stats

SCENARIOS = {
    'N B K': ('white_noise', 'bias_instability', 'rate_random_walk'),
    'N B': ('white_noise', 'bias_instability'),
    'N K': ('white_noise', 'rate_random_walk'),
    'Q N B': ('quantization', 'white_noise', 'bias_instability'),
    'N B R': ('white_noise', 'bias_instability', 'rate_ramp'),
}
SHORT = {'quantization': 'Q', 'white_noise': 'N', 'bias_instability': 'B',
         'rate_random_walk': 'K', 'rate_ramp': 'R'}
#: Ranges of the crossing averaging times, as (lo, hi) fractions: 'NB' of tau0 x 10^x (x in
#: [0.5, 1.5] decades above tau0 ... ), the slow terms as fractions of the record T.
CROSSINGS = {
    'NB': (10.0, 300.0),        # N = flicker floor at 10..300 tau0
    'BK': (1 / 60.0, 1 / 20.0),  # K = flicker floor at T/60 .. T/20
    'BR': (1 / 60.0, 1 / 20.0),  # R = flicker floor at T/60 .. T/20
    'NK': (1 / 300.0, 1 / 30.0),  # K = N at T/300 .. T/30
    'QN': (3.0, 20.0),          # Q = N at 3 .. 20 tau0
}
FLOOR = 2.0 * math.log(2.0) / math.pi  # AVAR / B^2 of flicker at long tau
#: Terms the fit adds for the sensor, not the noise (a line seen in the spectrum): not scored.
NUISANCE = {'sinusoid'}


def _log_uniform(rng, lo, hi):
    return math.exp(rng.uniform(math.log(lo), math.log(hi)))


def draw_truth(scenario, rng, n, rate_hz):
    """Coefficients of one axis (SI) whose terms each dominate part of the curve."""
    dt = 1.0 / rate_hz
    t_rec = n * dt
    names = SCENARIOS[scenario]
    n_val = 1e-3 * _log_uniform(rng, 0.3, 3.0)
    truth = {'white_noise': n_val}
    b_val = None
    if 'bias_instability' in names:
        tau_nb = dt * _log_uniform(rng, *CROSSINGS['NB'])
        b_val = math.sqrt(n_val ** 2 / tau_nb / FLOOR)
        truth['bias_instability'] = b_val
    if 'rate_random_walk' in names:
        if b_val is not None:
            tau = t_rec * _log_uniform(rng, *CROSSINGS['BK'])
            truth['rate_random_walk'] = math.sqrt(3.0 * FLOOR * b_val ** 2 / tau)
        else:
            tau = t_rec * _log_uniform(rng, *CROSSINGS['NK'])
            truth['rate_random_walk'] = math.sqrt(3.0) * n_val / tau
    if 'rate_ramp' in names:
        tau = t_rec * _log_uniform(rng, *CROSSINGS['BR'])
        truth['rate_ramp'] = math.sqrt(2.0 * FLOOR) * b_val / tau
    if 'quantization' in names:
        tau = dt * _log_uniform(rng, *CROSSINGS['QN'])
        truth['quantization'] = n_val * math.sqrt(tau / 3.0)
    return truth


def independent_axis(truth, n, rate_hz, rng):
    """Rate samples of one axis from the textbook definitions (no package code)."""
    dt = 1.0 / rate_hz
    y = truth.get('white_noise', 0.0) * math.sqrt(rate_hz) * rng.standard_normal(n)
    if 'quantization' in truth:
        y += np.diff(truth['quantization'] * rng.standard_normal(n + 1)) / dt
    if 'bias_instability' in truth:
        span = scipy.fft.next_fast_len(4 * n, real=True)
        f = np.fft.rfftfreq(span, d=dt)
        gain = np.zeros_like(f)
        gain[1:] = truth['bias_instability'] * np.sqrt(rate_hz / (2.0 * math.pi * f[1:]))
        # white noise of unit variance has two-sided PSD dt; |gain|^2 dt = B^2 / (2 pi f)
        y += scipy.fft.irfft(scipy.fft.rfft(rng.standard_normal(span)) * gain, span)[:n]
    if 'rate_random_walk' in truth:
        y += np.cumsum(truth['rate_random_walk'] * math.sqrt(dt) * rng.standard_normal(n))
    if 'rate_ramp' in truth:
        y += truth['rate_ramp'] * dt * np.arange(n)
    return y


def package_axis(truth, n, rate_hz, rng):
    """Rate samples of one axis from :func:`imu_allan.core.simulation.simulate.simulate_axis`."""
    return simulate_axis({t: {'value': v} for t, v in truth.items()}, n, rate_hz, rng)


#: The sensor's processing drawn for a realistic record: internal rate (Hz), filter window
#: taps at that rate, LSB in output noise sigmas (log-uniform), chance of an aliased line and
#: its output amplitude in output noise sigmas (log-uniform), the line's input frequency (Hz).
INTERNAL_RATE = 1000.0
WINDOW_TAPS = (1, 32)
LSB_SIGMAS = (0.2, 3.0)
LINE_CHANCE = 0.5
LINE_SIGMAS = (0.1, 0.5)
LINE_INPUT_HZ = (20.0, 450.0)


def draw_processing(rng, rate_hz):
    """Draw a realistic sensor's processing for one axis (see the constants above)."""
    line = None
    if rng.uniform() < LINE_CHANCE:
        line = (rng.uniform(*LINE_INPUT_HZ), _log_uniform(rng, *LINE_SIGMAS))
    return {'taps': int(rng.integers(WINDOW_TAPS[0], WINDOW_TAPS[1] + 1)),
            'lsb_sigmas': _log_uniform(rng, *LSB_SIGMAS), 'line': line,
            'decimation': int(round(INTERNAL_RATE / rate_hz))}


def realistic_truth(truth, processing, rate_hz, slow, rng, samples=2_000_000):
    """
    Return the white-noise density a realistic record carries at low frequency (continuous).

    Two parts.  The filtered noise, exactly: output means of M taps D input samples apart have
    autocovariance sigma_in^2 max(0, M - k D) / M^2, so decimation folds it to a density^2 of
    N^2 D (M + 2 sum_k max(0, M - k D)) / M^2 (N^2 exactly when D divides M; a 3-tap window
    at D = 10 gives 3.3 N^2).  The rounding's, measured: where the noise spans many LSB it is
    d^2 / 12 per sample (Sheppard), but where it spans few its size depends on where the
    drift holds the signal within an LSB, and it correlates with the signal and from sample to
    sample.  So fresh white noise x goes through the same processing on the record's own slow
    part ``slow`` (which sets the offsets), is rounded, and the rounding's error e = q - slow - x
    is measured against that same x: the lag sums of its autocovariance and of its
    cross-covariance with x (over the lags the filter correlates, and two more), averaged over
    ``samples`` output samples.  Measuring only the difference keeps the Monte Carlo error to
    the rounding's own scatter (about 1e-4 of N at d = 3 sigma), far below N's interval.
    """
    m, d = processing['taps'], processing['decimation']
    fold = d * (m + 2.0 * sum(max(0, m - k * d) for k in range(1, m // d + 1))) / (m * m)
    n = slow.size
    lags = m // d + 3
    extra, count = 0.0, 0
    while count < samples:
        q, x = _processed(truth['white_noise'], processing, n, rng, slow, with_noise=True)
        e = q - slow - x
        e -= e.mean()
        x = x - x.mean()
        extra += np.dot(e, e) + 2.0 * np.dot(x, e)
        for k in range(1, lags):
            extra += 2.0 * (np.dot(e[:n - k], e[k:]) + np.dot(x[:n - k], e[k:])
                            + np.dot(e[:n - k], x[k:]))
        count += n
    density_sq = truth['white_noise'] ** 2 * fold + extra / count / rate_hz
    return {**truth, 'white_noise': math.sqrt(density_sq)}


def _output_sigma(truth, processing):
    """Output-sample std of the filtered white noise (what the LSB is measured against)."""
    return truth['white_noise'] * math.sqrt(INTERNAL_RATE / processing['taps'])


def _processed(n_density, processing, n, rng, slow, line=None, with_noise=False):
    """
    Return ``n`` output samples of a realistic sensor's processing.

    White noise of density ``n_density`` (and a line) at the internal rate, through the window,
    decimated, plus ``slow``, rounded to the LSB (and, ``with_noise``, the filtered white noise
    alone, before the slow part and the rounding).
    """
    d, m = processing['decimation'], processing['taps']
    n_in = n * d + m
    fast = n_density * math.sqrt(INTERNAL_RATE) * rng.standard_normal(n_in)
    if line is not None:
        f_in, amplitude = line
        w = 2.0 * math.pi * f_in / INTERNAL_RATE
        fast += amplitude * np.sin(w * np.arange(n_in) + rng.uniform(0.0, 2.0 * math.pi))
    csum = np.concatenate([[0.0], np.cumsum(fast)])
    x = ((csum[m:] - csum[:-m]) / m)[::d][:n]
    lsb = processing['lsb_sigmas'] * n_density * math.sqrt(INTERNAL_RATE / m)
    q = np.round((x + slow) / lsb) * lsb
    return (q, x) if with_noise else q


def realistic_axis(truth, n, rate_hz, rng, processing):
    """
    Rate samples of a realistic sensor from textbook parts (no package code): ``(y, slow)``.

    White noise at the internal rate (density N: per-sample std N sqrt(fs_in)), plus a line at
    an input frequency (it aliases after decimation), through a ``taps``-sample moving average,
    every ``decimation``-th sample kept; the slow terms (``slow``: the independent generator at
    the output rate; the filter does not touch them); rounded to an LSB.
    """
    slow = independent_axis({k: v for k, v in truth.items() if k != 'white_noise'}, n,
                            rate_hz, rng)
    line = None
    if processing['line'] is not None:
        f_in, sigmas = processing['line']
        w = 2.0 * math.pi * f_in / INTERNAL_RATE
        m = processing['taps']
        gain = abs(math.sin(w * m / 2.0) / (m * math.sin(w / 2.0)))  # the window's response
        line = (f_in, sigmas * _output_sigma(truth, processing) / max(gain, 1e-3))
    return _processed(truth['white_noise'], processing, n, rng, slow, line), slow


GENERATORS = {'independent': independent_axis, 'package': package_axis}


def batch(scenario, generator, hours, rate_hz, n_axes, seed, chunk=6, hadamard=False,
          processing='measured'):
    """
    Simulate and fit ``n_axes`` axes; return ``[(truth, fitted, axis), ...]``.

    Axes are generated ``chunk`` (at most 6: the package's axis names) at a time into one
    (n, chunk) array, their Allan variances computed in one call and fitted together; with
    ``hadamard`` the fit also sees the OHDEV curve (:mod:`imu_allan.core.fit.hadamard_check`).
    The fit is given the sensor's processing as
    :func:`imu_allan.core.sensor.measure.measure_sensor` measures it from the samples
    (``processing='measured'``, what ``analyze`` does), as the realistic generator made it
    (``'known'``: the device's window, the line), or not at all (None).  For realistic records the
    truth is :func:`realistic_truth`.
    """
    rng = np.random.default_rng(seed)
    n = int(round(hours * 3600.0 * rate_hz))
    ms = tau_grid(n)
    out = []
    for start in range(0, n_axes, chunk):
        count = min(chunk, n_axes - start)
        data = np.empty((n, count))
        truths, known = [], {}
        for j in range(count):
            truth = draw_truth(scenario, rng, n, rate_hz)
            if generator == 'realistic':
                proc = draw_processing(rng, rate_hz)
                data[:, j], slow = realistic_axis(truth, n, rate_hz, rng, proc)
                known[AXES[j]] = _known_processing(truth, proc, rate_hz)
                truth = realistic_truth(truth, proc, rate_hz, slow, rng)
            else:
                data[:, j] = GENERATORS[generator](truth, n, rate_hz, rng)
            truths.append(truth)
        result = AllanResult.from_avar(ms, avar_fast(data, ms), n, rate_hz, axes=AXES[:count])
        curves = ({'ohdev': deviation(data, rate_hz, 'ohdev', axes=AXES[:count])}
                  if hadamard else None)
        proc = None
        if processing == 'measured':
            from imu_allan.core.sensor.measure import measure_sensor
            proc = measure_sensor(data, rate_hz, AXES[:count]).processing()
        elif processing == 'known' and known:
            proc = known
        del data
        fitted = fit_noise_model(result, deviations=curves, processing=proc)
        out += [(truth, fitted, axis) for truth, axis in zip(truths, AXES)]
    return out


def _known_processing(truth, proc, rate_hz):
    """
    Return the realistic generator's processing as the fit takes it: filter, aliased line.

    The output's autocovariance (in units of sigma_in^2 / M^2): M + d^2 / 12 at lag 0 (the
    rounding, d in those units), M - k D at lag k while positive.
    """
    m, d = proc['taps'], proc['decimation']
    cov = [m - k * d for k in range(1, m // d + 1) if m - k * d > 0]
    lsb = proc['lsb_sigmas'] * math.sqrt(m)  # sigma_out = sqrt(M) in these units
    s = m + lsb * lsb / 12.0 + 2.0 * sum(cov)
    moment = 2.0 * sum(k * c for k, c in enumerate(cov, 1)) / s
    lines = ()
    if proc['line'] is not None:
        f_in, sigmas = proc['line']
        alias = abs(f_in - rate_hz * round(f_in / rate_hz))
        lines = ((alias, sigmas * _output_sigma(truth, proc)),)
    return Processing(len(cov), moment, lines)


def score(cases, levels=(CI_LEVEL, 0.95)):
    """Per-axis outcomes: selection, alternatives, and per true term the coverage flags."""
    rows = []
    for truth, fitted, axis in cases:
        # the selected set (what the criterion chose; the resolved terms are its part that
        # every open set holds, and coverage is scored on those)
        chosen = set(fitted.fits[axis].terms) - NUISANCE
        resolved = set(fitted.model.terms.get(axis, {})) - NUISANCE
        alternatives = [set(a) - NUISANCE for a in fitted.alternatives(axis)]
        fit = fitted.fits[axis]
        crits = {frozenset(names) - NUISANCE: crit for crit, names in fit.candidates}
        best = fit.candidates[0][0] if fit.candidates else math.nan
        row = {'exact': chosen == set(truth), 'resolved_exact': resolved == set(truth),
               'gap': crits.get(frozenset(truth), math.inf) - best,
               'among': any(a == set(truth) for a in alternatives),
               'n_alternatives': len(alternatives), 'cover': {},
               # the Hadamard check: ran (open sets differing in K), rejected the true set
               'checked': bool(fit.evidence),
               'truth_rejected': any(set(e['terms']) == set(truth) and e['rejected']
                                     for e in fit.evidence),
               'adequacy_p': fit.adequacy.p if fit.adequacy is not None else math.nan}
        for term, value in truth.items():
            if term not in resolved:
                continue
            row['cover'][term] = [_inside(fitted.interval(axis, term, level=lv), value)
                                  for lv in levels]
        rows.append(row)
    return rows


def _inside(interval, value):
    lo, hi = interval
    return bool(lo <= value <= hi)


CELLS = [(s, g, h, r) for s in SCENARIOS for g in GENERATORS for h, r in
         ((1.0, 100.0), (3.0, 100.0), (1.0, 400.0))]
#: The realistic table of docs/method.md section 10, per rate (no quantization scenario: the
#: rounding is the sensor's, in every record); seeds 900, 901, ... in this order.
REALISTIC_CELLS = {rate: [(s, 'realistic', 1.0, rate) for s in SCENARIOS if s != 'Q N B']
                   for rate in (100.0, 200.0)}


def run(cells=CELLS, n_axes=24, seed=1, log=None, hadamard=False, seed_step=1000):
    """Return ``{cell: rows}`` for every (scenario, generator, hours, rate) cell."""
    out = {}
    for k, cell in enumerate(cells):
        t0 = time.process_time()
        out[cell] = score(batch(*cell, n_axes, seed + seed_step * k, hadamard=hadamard))
        if log:
            log(f'{cell}: {time.process_time() - t0:.1f} s CPU')
    return out


def summary(outcomes):
    """Aggregate: selection rates and per-term coverage over all cells."""
    rows = [r for rs in outcomes.values() for r in rs]
    cover = {}
    for r in rows:
        for term, flags in r['cover'].items():
            cover.setdefault(term, []).append(flags)
    return {'axes': len(rows),
            'exact': float(np.mean([r['exact'] for r in rows])),
            'resolved_exact': float(np.mean([r['resolved_exact'] for r in rows])),
            'among': float(np.mean([r['among'] or r['exact'] for r in rows])),
            # share of axes whose true set is within a criterion margin of the best
            'within': {m: float(np.mean([r['gap'] < m for r in rows])) for m in (2, 6, 10)},
            'cover': {t: (len(f), *np.mean(np.array(f, dtype=float), axis=0))
                      for t, f in cover.items()}}


def table(outcomes):
    """Markdown table: one row per scenario x generator, then the total."""
    lines = ['| truth | generator | axes | selected = truth | truth among alternatives | '
             'mean alternatives | 68.3 % / 95 % coverage per term (cases) |',
             '|---|---|---|---|---|---|---|']
    groups = {}
    for (s, g, h, r), rows in outcomes.items():
        groups.setdefault((s, g), {})[(s, g, h, r)] = rows
    for (s, g), cells in list(groups.items()) + [(('all', ''), outcomes)]:
        agg = summary(cells)
        rows = [r for rs in cells.values() for r in rs]
        cover = ', '.join(f'{SHORT[t]} {100 * c68:.0f} / {100 * c95:.0f} ({n})'
                          for t, (n, c68, c95) in sorted(agg['cover'].items(),
                                                         key=lambda x: 'QNBKR'.index(SHORT[x[0]])))
        lines.append(f'| {s} | {g} | {agg["axes"]} | {100 * agg["exact"]:.0f} % | '
                     f'{100 * agg["among"]:.0f} % | '
                     f'{np.mean([r["n_alternatives"] for r in rows]):.2f} | {cover} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    # python test/core/calibration_cases.py [axes per cell] [--hadamard | --realistic]
    args = [a for a in sys.argv[1:] if not a.startswith('--')]
    axes = int(args[0]) if args else 24
    t0 = time.process_time()

    def log(text):
        print(text, file=sys.stderr, flush=True)

    if '--realistic' in sys.argv:
        for rate, cells in REALISTIC_CELLS.items():
            result = run(cells, n_axes=axes, seed=900, log=log, seed_step=1)
            p = np.array([r['adequacy_p'] for rs in result.values() for r in rs])
            p = p[np.isfinite(p)]
            print(f'\n{rate:.0f} Hz\n\n{table(result)}\n\nadequacy p against uniform: '
                  f'Kolmogorov-Smirnov p = {scipy.stats.kstest(p, "uniform").pvalue:.2f}; '
                  f'p < 0.001 on {100 * np.mean(p < 0.001):.1f} % of {p.size} axes')
        sys.exit(0)
    result = run(n_axes=axes, log=log, hadamard='--hadamard' in sys.argv)
    print(table(result))
    rows = [r for rs in result.values() for r in rs]
    if any(r['checked'] for r in rows):
        print(f'\nHadamard check ran on {sum(r["checked"] for r in rows)} axes, rejected the '
              f'true set on {sum(r["truth_rejected"] for r in rows)}')
    within = summary(result)['within']
    print('\ntrue set within a criterion margin of the best: ' + ', '.join(
        f'{m}: {100 * v:.1f} %' for m, v in within.items()))
    print(f'\n{time.process_time() - t0:.0f} s CPU', file=sys.stderr)
