"""
Evidence that needs several runs: the turn-on bias and the sign of a drift.

Turn-on bias (``turn_on_bias: {mean, sigma}``, one value drawn per start): each run's mean over
its first tenth, b_r, estimates the bias it started with; under the model b_r ~ N(mean,
sigma^2 + v_r), v_r the noise within the run (:func:`.evidence._mean_noise`).  Four tests
against it (:func:`turn_on_tests`): *decay* (b_last = beta b_first across runs, corrected for
the noise in b_first; factor beta), *bimodal* (runs of the opposite sign against
Phi(-|mean| / sd); factor the sign agreement 1 - 2 share), *spread* (chi-square; factor
sqrt(var - v) / sigma) and *mean* (factor observed / stated).  An accelerometer axis whose runs
sit beyond :data:`GRAVITY_LEVEL` carries gravity: decay (with an intercept) and spread only.

Drift with a biased drive (a drive with a non-zero mean drifts the same way in every run and
axis): :func:`drive_test`.  All intervals are 68.3 % and 95 % (t or chi-square quantiles for the
few runs there are).  docs/discrepancy.md section 8 ("Across runs") gives the reasoning.
"""

import math

import numpy as np
from scipy.stats import binom, chi2, norm
from scipy.stats import t as student

from .band import Z95
from ..terms import TERMS
from ..units import discrete_random_walk_step

#: An accelerometer axis whose run means exceed this (m/s^2) carries gravity.
GRAVITY_LEVEL = 1.0
#: Fewest runs for a run-to-run test.
MIN_RUNS = 3
_P68, _P95 = norm.cdf(1.0) - norm.cdf(-1.0), 0.95


def _tq(dof, level=_P68):
    """Two-sided t quantile of a central interval at ``level``."""
    return float(student.ppf(0.5 + level / 2.0, dof))


def _finding(kind, factor, ci, ci95, p, evidence):
    return {'kind': kind, 'factor': factor, 'factor_ci': ci, 'factor_ci95': ci95,
            'p_value': p, 'evidence': evidence}


def _t_intervals(value, se, dof):
    """68.3 % and 95 % t intervals of ``value`` with standard error ``se``."""
    return ([value - _tq(dof) * se, value + _tq(dof) * se],
            [value - _tq(dof, _P95) * se, value + _tq(dof, _P95) * se])


def _decay(first, last, noise, gravity):
    """Slope of last on first across runs, corrected for the noise in ``first``."""
    r = first.size
    if gravity:
        x, y = first - first.mean(), last - last.mean()
        dof = r - 2
    else:
        x, y = first, last
        dof = r - 1
    sxx = float(np.dot(x, x))
    noise_sum = float(np.sum(noise)) * (1.0 - 1.0 / r if gravity else 1.0)
    if dof < 1 or sxx <= 2.0 * noise_sum:  # the turn-on bias hides in the noise: no test
        return None
    beta = float(np.dot(x, y)) / sxx
    resid = y - beta * x
    se = math.sqrt(float(np.dot(resid, resid)) / dof / sxx)
    attenuation = sxx / (sxx - noise_sum)
    beta, se = beta * attenuation, se * attenuation
    if se <= 0:
        return None
    p = float(2.0 * student.sf(abs(beta - 1.0) / se, dof))
    ci, ci95 = _t_intervals(beta, se, dof)
    return _finding('decay', beta, ci, ci95, p,
                    {'first_tenth_means': first.tolist(), 'last_tenth_means': last.tolist()})


def _bimodal(first, noise, mean, sigma):
    """Test the runs on the wrong side of zero against the stated probability."""
    if mean == 0:
        return None
    r = first.size
    sd = math.sqrt(sigma ** 2 + float(np.mean(noise)))
    p0 = float(norm.sf(abs(mean) / sd)) if sd > 0 else 0.0
    flips = int(np.sum(np.sign(first) != np.sign(mean)))
    p = float(binom.sf(flips - 1, r, p0)) if flips else 1.0
    share = flips / r
    return _finding('bimodal', 1.0 - 2.0 * share, _agreement(share, r, 1.0),
                    _agreement(share, r, Z95), p,
                    {'opposite_sign_runs': flips, 'runs': r, 'stated_share': p0})


def _agreement(share, r, z):
    """Wilson interval (z) of the opposite-sign share, as the sign agreement 1 - 2 share."""
    z2 = z * z
    centre = (share + z2 / (2 * r)) / (1.0 + z2 / r)
    half = z * math.sqrt(share * (1.0 - share) / r + z2 / (4 * r * r)) / (1.0 + z2 / r)
    return [1.0 - 2.0 * (centre + half), 1.0 - 2.0 * (centre - half)]


def _spread(first, noise, sigma):
    """Sample variance of the turn-on estimates against the stated sigma^2 + noise."""
    r = first.size
    var = float(np.var(first, ddof=1))
    v = float(np.mean(noise))
    expected = sigma ** 2 + v
    stat = (r - 1) * var / expected if expected > 0 else math.inf
    p = float(2.0 * min(chi2.cdf(stat, r - 1), chi2.sf(stat, r - 1)))
    observed = math.sqrt(max(var - v, 0.0))
    evidence = {'observed_sigma': observed, 'stated_sigma': sigma, 'noise_sigma': math.sqrt(v)}
    if sigma <= 0:
        return _finding('spread', None, None, None, p, evidence)

    def interval(level):  # chi-square interval of the variance, less the noise's share
        lo_q, hi_q = chi2.ppf([0.5 + level / 2.0, 0.5 - level / 2.0], r - 1)
        return [math.sqrt(max((r - 1) * var / q - v, 0.0)) / sigma for q in (lo_q, hi_q)]
    return _finding('spread', observed / sigma, interval(_P68), interval(_P95), p, evidence)


def _mean(first, noise, mean, sigma):
    """Mean of the turn-on estimates against the stated mean."""
    r = first.size
    m = float(np.mean(first))
    sd = math.sqrt((sigma ** 2 + float(np.mean(noise))) / r)
    p = float(2.0 * norm.sf(abs(m - mean) / sd)) if sd > 0 else (0.0 if m != mean else 1.0)
    se = math.sqrt(float(np.var(first, ddof=1)) / r)
    evidence = {'observed_mean': m, 'stated_mean': mean}
    if mean == 0:
        return _finding('mean', None, None, None, p, evidence)
    ci, ci95 = _t_intervals(m / mean, se / abs(mean), r - 1)
    return _finding('mean', m / mean, ci, ci95, p, evidence)


def turn_on_tests(axis, evidences, stated):
    """
    Run-to-run tests of one axis: each that the runs allow, with its p-value.

    ``evidences``: the axis's AxisEvidence per run; ``stated``: the model's ``{'mean',
    'sigma'}``.  Returns ``[{'kind', 'factor', 'factor_ci', 'factor_ci95', 'p_value',
    'evidence'}]``; the caller decides.
    """
    if len(evidences) < MIN_RUNS:
        return []
    first = np.array([e.means['first'] for e in evidences])
    last = np.array([e.means['last'] for e in evidences])
    noise = np.array([e.mean_noise_var.get('first', 0.0) for e in evidences])
    gravity = not axis.startswith('gyro') and abs(float(np.median(first))) > GRAVITY_LEVEL
    out = [_decay(first, last, noise, gravity)]
    if not gravity:
        out += [_bimodal(first, noise, stated['mean'], stated['sigma']),
                _mean(first, noise, stated['mean'], stated['sigma'])]
    out = [t for t in out + [_spread(first, noise, stated['sigma'])] if t is not None]
    for test in out:
        test['evidence']['gravity_axis'] = gravity
    return out


def _ramp_gain(tau_c, duration_s):
    """
    OLS slope over [0, T] of the mean a biased drive adds, per unit of (mean step x rate).

    A walk gains the drive's mean every step: slope 1.  A Gauss-Markov levels off at
    tau_c (mean x rate): the slope of tau_c (1 - exp(-t / tau_c)) over the record.
    """
    if tau_c is None or not math.isfinite(tau_c):
        return 1.0
    t = np.linspace(0.0, duration_s, 2001)
    g = tau_c * -np.expm1(-t / tau_c)
    tc = t - t.mean()
    return float(np.dot(tc, g - g.mean()) / np.dot(tc, tc))


def _drive(stated_terms, rate_hz):
    """(per-step std of the stated drive, its tau_c or None) or None without a drive term."""
    if 'rate_random_walk' in stated_terms:
        return discrete_random_walk_step(stated_terms['rate_random_walk']['value'],
                                         rate_hz), None
    if 'gauss_markov' in stated_terms:
        sigma, tau_c = TERMS['gauss_markov'].unpack(stated_terms['gauss_markov'])
        return sigma * math.sqrt(-math.expm1(-2.0 / (rate_hz * tau_c))), tau_c
    return None


def _slope_variance(terms, rate_hz, duration_s):
    """
    Variance of a record's least-squares slope under ``terms``, up to a common factor.

    2 AVAR(T/2) / (T/2)^2, the variance of the difference of the two halves' means over half
    the record: the OLS slope's variance is 0.75 of it for white noise and 0.9 for a random
    walk, so it weighs records of different lengths and rates against each other (the scale
    itself is estimated from the slopes, :func:`drive_test`).
    """
    from ..terms import model_avar
    half = 0.5 * duration_s
    return 2.0 * float(model_avar(terms, np.array([half]), rate_hz)[0]) / half ** 2


def _run_factors(evs, stated):
    """
    Each run's drive factor (mean step / stated step sd) and its relative variance, or None.

    None when the axis states no drive (a random walk or a Gauss-Markov).
    """
    out = []
    for e in evs:
        drive = _drive(stated, e.rate_hz)
        if drive is None or not math.isfinite(e.slope_per_s):
            return None
        step_sd, tau_c = drive
        per_slope = 1.0 / (e.rate_hz * _ramp_gain(tau_c, e.duration_s) * step_sd)
        out.append((e.slope_per_s * per_slope,
                    _slope_variance(stated, e.rate_hz, e.duration_s) * per_slope ** 2))
    return out


def _sign_p(slopes):
    """Two-sided binomial(n, 1/2) p-value of the positive count among ``slopes``."""
    n, k = len(slopes), int(np.sum(np.array(slopes) > 0))
    return float(min(1.0, 2.0 * min(binom.cdf(k, n, 0.5), binom.sf(k - 1, n, 0.5))))


def drive_test(per_axis, stated_terms):
    """
    Test one sensor's drift over all its runs and axes for a drive with a mean; each axis's factor.

    Two tests, the smaller p-value doubled (Bonferroni): the slopes' signs against
    binomial(n, 1/2), and a t test, t(n - 1), of the runs' drive factors (mean step / stated
    step sd) weighted by :func:`_slope_variance`, the scale from their scatter (it needs no
    stated scale; docs/discrepancy.md section 8 says why both).  An axis's factor is its runs'
    weighted mean with that pooled scatter (t intervals): the axes of a sensor share the drive.
    ``per_axis``: ``{axis: [AxisEvidence per run]}``; ``stated_terms``: ``{axis: terms}``.
    Returns ``(p_value, {axis: {'factor', 'factor_ci', 'factor_ci95', 'evidence'}})``; both
    tests need at least :data:`MIN_RUNS` slopes.
    """
    slopes = [e.slope_per_s for evs in per_axis.values() for e in evs
              if math.isfinite(e.slope_per_s)]
    if len(slopes) < MIN_RUNS:
        return 1.0, {}
    p_sign = _sign_p(slopes)
    factors = {a: _run_factors(evs, stated_terms.get(a, {})) for a, evs in per_axis.items()}
    f = np.array([x for v in factors.values() if v for x, _ in v])
    w = 1.0 / np.array([v for fs in factors.values() if fs for _, v in fs])
    p_t, scatter, dof = 1.0, None, f.size - 1
    if f.size >= MIN_RUNS and np.all(np.isfinite(w) & (w > 0)):
        mean = float(np.sum(w * f) / np.sum(w))
        scatter = float(np.sum(w * (f - mean) ** 2)) / dof  # variance at unit weight
        if scatter > 0:
            p_t = float(2.0 * student.sf(abs(mean) / math.sqrt(scatter / np.sum(w)), dof))
    p = min(1.0, 2.0 * min(p_sign, p_t))
    out = {}
    for axis, evs in per_axis.items():
        same = [e.slope_per_s for e in evs]
        entry = {'factor': None, 'factor_ci': None, 'factor_ci95': None,
                 'evidence': {'slopes_per_s2': same, 'positive_runs': int(np.sum(
                     np.array(same) > 0)), 'runs': len(same), 'p_sign': p_sign, 'p_t': p_t}}
        fs = factors[axis]
        if fs and scatter:
            fa, wa = np.array([x for x, _ in fs]), 1.0 / np.array([v for _, v in fs])
            m = float(np.sum(wa * fa) / np.sum(wa))
            ci, ci95 = _t_intervals(m, math.sqrt(scatter / np.sum(wa)), dof)
            entry.update(factor=m, factor_ci=ci, factor_ci95=ci95)
            entry['evidence']['run_factors'] = fa.tolist()
        out[axis] = entry
    return p, out
