"""
Minimum of a function of one variable on an interval: Brent's method.

The method of R. P. Brent (1973), "Algorithms for Minimization without Derivatives", ch. 5,
in the form of Forsythe, Malcolm & Moler (1977), "Computer Methods for Mathematical
Computations", procedure ``fmin``: golden-section steps, replaced by parabolic interpolation
through the three best points whenever the parabola's step is inside the interval and shorter
than half the step before last.  It is what ``scipy.optimize.minimize_scalar(method='bounded')``
computes, point for point (a test compares them); the fits use it here because importing
``scipy.optimize`` costs 0.3 s, a third of a one-minute ``analyze`` (see
:mod:`..scipy_compiled`).
"""

import math

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))  # the golden-section fraction, 0.381966...


def bounded_minimum(f, lo, hi, xatol=1e-5, max_evaluations=500):
    """
    Return ``(x, f(x))`` at a local minimum of ``f`` on ``[lo, hi]`` (finite, lo <= hi).

    ``x`` is located to about ``xatol`` plus a relative 1.5e-8.  ``f`` is evaluated at most
    ``max_evaluations`` times, never at the bounds themselves.
    """
    a, b = float(lo), float(hi)
    # x: best point so far; w: second best; v: the previous w.  f values fx, fw, fv.
    x = w = v = a + _GOLDEN * (b - a)
    fx = fw = fv = f(x)
    evaluations = 1
    step = last_step = 0.0  # d and e of Brent's text: this step and the one before
    mid = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(x) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(x - mid) > tol2 - 0.5 * (b - a):
        parabolic = False
        if abs(last_step) > tol1:
            # the parabola through (v, fv), (w, fw), (x, fx): its vertex is x + p / q
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            older, last_step = last_step, step
            if abs(p) < abs(0.5 * q * older) and q * (a - x) < p < q * (b - x):
                parabolic = True
                step = p / q
                u = x + step
                if u - a < tol2 or b - u < tol2:  # not that close to a bound: tol1 inwards
                    step = tol1 if mid >= x else -tol1
        if not parabolic:
            last_step = (a if x >= mid else b) - x
            step = _GOLDEN * last_step
        # never closer than tol1 to x: the difference would be rounding noise
        u = x + (math.copysign(max(abs(step), tol1), step) if step != 0.0 else tol1)
        fu = f(u)
        evaluations += 1
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
        mid = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(x) + xatol / 3.0
        tol2 = 2.0 * tol1
        if evaluations >= max_evaluations:
            break
    return x, fx
