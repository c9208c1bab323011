"""Brent's bounded minimisation, point for point what scipy's ``minimize_scalar`` computes."""

import math

from imu_allan.core.fit.bounded_min import bounded_minimum
import numpy as np
import pytest
from scipy.optimize import minimize_scalar


def _functions(seed, count=400):
    """Smooth, kinked, stepped (ties) and linear functions on random intervals."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        c = rng.normal(size=3)
        lo = rng.uniform(-3.0, 0.0)
        hi = lo + rng.uniform(0.01, 5.0)
        f = [lambda x, c=c: (x - c[0]) ** 2 + c[1] * math.sin(3.0 * x),
             lambda x, c=c: abs(x - c[0]),
             lambda x, c=c: round((x - c[0]) ** 2, 3),
             lambda x, c=c: c[0] * x][i % 4]
        yield f, lo, hi, 10.0 ** rng.uniform(-6.0, -1.0)


def test_same_points_and_values_as_scipy():
    for f, lo, hi, xatol in _functions(0):
        expected = minimize_scalar(f, bounds=(lo, hi), method='bounded',
                                   options={'xatol': xatol})
        assert bounded_minimum(f, lo, hi, xatol=xatol) == (expected.x, expected.fun)


def test_finds_an_interior_minimum_and_respects_the_evaluation_budget():
    calls = []

    def f(x):
        calls.append(x)
        return (x - 0.3) ** 2
    x, fx = bounded_minimum(f, -1.0, 2.0, xatol=1e-8)
    assert x == pytest.approx(0.3, abs=1e-7) and fx == pytest.approx(0.0, abs=1e-13)
    assert all(-1.0 < c < 2.0 for c in calls)  # never at the bounds
    calls.clear()
    bounded_minimum(f, -1.0, 2.0, xatol=1e-12, max_evaluations=5)
    assert len(calls) == 5
