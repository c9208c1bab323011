"""
Bisection, and the same bisection in fewer evaluations when each evaluation also says how far.

The recording advisor's forecast times and the fits' upper limits are found by bisection: a
fixed number of halvings of an interval [lo, hi] on which a predicate ``ok(x)``, monotone in x
(false below a crossing, true above it), is false at lo and true at hi.  Every evaluation there
is a fit, and the predicate comes from a smooth quantity (a predicted interval, a chi^2
difference) that says how far the crossing is.  :func:`guided` uses that to guess the crossing
(regula falsi, Illinois variant: G. Dahlquist & A. Bjorck (1974), "Numerical Methods",
sec. 6.2.2), takes the cell of the bisection grid the guess lies in, and evaluates the
predicate at that cell's two ends.  False at the lower end and true at the upper end means
bisection ends in that cell: each decision on bisection's way there is implied by one of the
two, as the predicate is monotone.  So :func:`guided` returns exactly what :func:`bisection`
returns (tests compare them), in about 4 evaluations instead of 10 to 16.  A wrong guess still
narrows the bracket for the next one.
"""

import math


def bisection(ok, lo, hi, steps):
    """
    Halve [lo, hi] ``steps`` times, keeping ``ok`` false at lo and true at hi; return (lo, hi).

    The reference for :func:`guided`.  A generator: it yields before each evaluation (the
    advisor interleaves other work there); the pair is its return value.
    """
    for _ in range(steps):
        yield
        mid = 0.5 * (lo + hi)
        if ok(mid):
            hi = mid
        else:
            lo = mid
    return lo, hi


def halve(below, lo, hi, steps, tol=0.0):
    """
    Return the midpoint of [lo, hi] after ``steps`` halvings toward the crossing of ``below``.

    ``below(x)``: the crossing lies above x (monotone); stops early once hi - lo < ``tol``.
    """
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        if below(mid):
            lo = mid
        else:
            hi = mid
        if hi - lo < tol:
            break
    return 0.5 * (lo + hi)


def guided(evaluate, lo, hi, steps, levels, key=None, hi_known=True):
    """
    Return the (lo, hi) of :func:`bisection` with ``ok(x) = evaluate(x)[0]``, sooner.

    ``evaluate(x)`` returns ``(ok, level)``: the predicate and a number roughly linear in x
    that is negative where ok is false and crosses 0 about where ok turns true (only used to
    guess; with NaN or a wrong sign at an end of the bracket it takes a bisection step).
    ``levels`` are the levels at lo (ok false there) and at hi.  ``hi_known=False``: ok at hi
    is not known either and its level is a guess; hi is evaluated only if the search gets
    there, and None is returned if ok is false at hi (bisection would not have started).
    ``key(x)`` is what the predicate depends on, monotone in x (default x itself): points
    with equal keys share an answer (the advisor evaluates whole numbers of samples,
    round(exp(x))).  A generator like :func:`bisection`.
    """
    key = key or (lambda x: x)
    below, above = [lo, levels[0]], [hi, levels[1]]  # the bracket: (x, level), false / true
    moved, streak = None, 0  # the end that moved last (Illinois), and how often in a row

    def known(x):  # the answer at x if evaluated or implied by monotonicity, else None
        k = key(x)
        if k <= key(below[0]):
            return False
        if k >= key(above[0]) and (hi_known or above[0] != hi):
            return True
        return None

    while True:
        # A good guess moves one end, then the other; the same end three times in a row
        # (a poor guide: flat or noisy levels) gives way to a bisection step.
        guess = _regula_falsi(below, above) if streak < 3 else None
        a, b = lo, hi
        first_open = None  # the first point on the path whose answer is not known
        for _ in range(steps):  # bisection's path: answers known or implied, else the guess
            mid = 0.5 * (a + b)
            answer = known(mid)
            if answer is None:
                first_open = mid if first_open is None else first_open
                answer = guess is not None and mid >= guess
            if answer:
                b = mid
            else:
                a = mid
        open_ends = [x for x in (a, b) if known(x) is None]
        if not open_ends:  # b is false only if hi is (its key equals a false point's)
            return (a, b) if known(b) else None
        if guess is None:  # bisection's own next point (hi, when only hi is left open)
            x = first_open if first_open is not None else open_ends[-1]
        else:  # the guessed cell's open end nearer the guess (the next guess asks the other)
            x = min(open_ends, key=lambda x: abs(x - guess))
        yield
        ok, level = evaluate(x)
        if x == hi:
            if not ok:
                return None
            hi_known = True
        end, other = (above, below) if ok else (below, above)
        end[:] = [x, level]
        streak = streak + 1 if moved is end else 1
        if streak > 1:
            other[1] *= 0.5
        moved = end


def _regula_falsi(below, above):
    """Where the levels at the bracket's ends interpolate to 0 (None if they cannot)."""
    (a, v_a), (b, v_b) = below, above
    if math.isfinite(v_a) and math.isfinite(v_b) and v_a < 0.0 <= v_b:
        return a + (b - a) * (-v_a) / (v_b - v_a)
    return None


def log_ratio(a, b):
    """log(a / b): a level for :func:`guided` when ok is a >= b (NaN where undefined)."""
    try:
        return math.log(a / b)
    except (ValueError, ZeroDivisionError):
        return math.nan


def run(generator):
    """Run a generator of this module to its end; return its value."""
    while True:
        try:
            next(generator)
        except StopIteration as stop:
            return stop.value
