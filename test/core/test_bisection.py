"""The guided search returns exactly what bisection returns, in fewer evaluations."""

import math

from imu_allan.core.fit.advisor import _crossing, bisection_crossing
from imu_allan.core.fit.bisection import bisection, guided, log_ratio, run
import numpy as np
import pytest


def _counted(fn):
    calls = []

    def wrapped(x):
        calls.append(x)
        return fn(x)
    return wrapped, calls


def _cases(seed, count=300):
    """(crossing, level function) pairs: exact, noisy, curved, flat and NaN-ridden levels."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        root = rng.uniform(0.0, 10.0)
        slope = 10.0 ** rng.uniform(-1.0, 1.0)
        kind = i % 5
        if kind == 0:  # linear: regula falsi is exact
            def level(x, root=root, slope=slope):
                return slope * (x - root)
        elif kind == 1:  # saturating on one side, like chi^2 with model weights
            def level(x, root=root, slope=slope):
                return math.tanh(slope * (x - root)) * 5.0
        elif kind == 2:  # the right sign, a wrong shape, a little noise
            noise = rng.normal(size=4096) * 0.05

            def level(x, root=root, noise=noise):
                return (x - root) ** 3 + noise[int(x * 100) % 4096]
        elif kind == 3:  # no usable level at all: plain bisection steps
            def level(x):
                return math.nan
        else:  # levels whose zero is far from the crossing (a poor guide)
            def level(x, root=root, slope=slope):
                return slope * (x - root + 3.0)
        yield root, level


@pytest.mark.parametrize('steps', [10, 16])
def test_guided_ends_in_the_cell_bisection_ends_in(steps):
    spent = np.zeros((5, 2))  # per kind of level: evaluations guided, bisection
    for i, (root, level) in enumerate(_cases(steps)):
        ok = root.__le__  # true from the crossing up (x >= root)
        evaluate, calls = _counted(lambda x, level=level, ok=ok: (ok(x), level(x)))
        reference, ref_calls = _counted(ok)
        expected = run(bisection(reference, 0.0, 10.0, steps))
        assert run(guided(evaluate, 0.0, 10.0, steps, (level(0.0), level(10.0)))) == expected
        spent[i % 5] += len(calls), len(ref_calls)
    ratio = spent[:, 0] / spent[:, 1]
    assert ratio[0] < 0.3 and ratio[1] < 0.6  # good guides: linear, saturating levels
    assert ratio[3] == 1.0  # no levels: bisection itself
    assert np.all(ratio < 1.5)  # a poor guide costs little more: bisection steps take over


def test_integer_keys_and_an_unknown_upper_end():
    """As the advisor uses it: whole numbers of samples, n_max evaluated only if reached."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        n0 = int(rng.integers(50, 100_000))
        n_max = n0 * 10_000
        crossing = int(n0 * 10.0 ** rng.uniform(-0.1, 4.3))  # sometimes never, or at once

        def ok(n, crossing=crossing):
            return n >= crossing

        def evaluate(n, crossing=crossing):
            return ok(n), 0.7 * math.log(n / crossing)
        counted, calls = _counted(evaluate)
        got = run(_crossing(counted, n0, n_max, 0.5))
        assert got == run(bisection_crossing(ok, n0, n_max))
        if crossing <= n_max // 2:
            assert n_max not in calls  # found below it: the costliest forecast is skipped


def test_non_finite_and_wrong_signed_levels_fall_back_to_bisection_steps():
    for levels in [(math.nan, math.nan), (1.0, -1.0), (-math.inf, math.inf)]:
        evaluate, calls = _counted(lambda x, levels=levels: (x >= 3.3, levels[0]))
        assert run(guided(evaluate, 0.0, 10.0, 12, levels)) == run(
            bisection(lambda x: x >= 3.3, 0.0, 10.0, 12))
        assert len(calls) <= 12


def test_log_ratio_is_nan_where_undefined():
    assert log_ratio(math.e, 1.0) == pytest.approx(1.0)
    assert all(math.isnan(log_ratio(a, b)) for a, b in [(0.0, 1.0), (-1.0, 1.0), (1.0, 0.0)])
