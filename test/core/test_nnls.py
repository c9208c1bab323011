"""The fits' NNLS equals scipy's public ``nnls`` and keeps its refusals."""

from imu_allan.core.fit import nnls as core_nnls
import numpy as np
import pytest
from scipy.optimize import nnls as scipy_nnls


def _problems(seed, count=300):
    """Random small problems like the fits' (3-40 rows, 1-7 columns), some degenerate."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        a = rng.normal(size=(rng.integers(3, 41), rng.integers(1, 8)))
        if rng.random() < 0.2:  # two nearly equal columns (quantization vs white noise)
            a[:, -1] = a[:, 0] * (1.0 + 1e-7 * rng.normal(size=a.shape[0]))
        if rng.random() < 0.1:
            a[:, 0] = 0.0
        yield a, rng.normal(size=a.shape[0]) * 10.0 ** rng.uniform(-3, 3)


def test_compiled_path_equals_scipy_public_nnls():
    """Bit for bit: the same routine is called, only the argument checks are skipped."""
    assert core_nnls._compiled_nnls is not None  # the pinned scipy has it; else no speed-up
    for a, b in _problems(0):
        expected = scipy_nnls(a, b, maxiter=50 * a.shape[1])[0]
        assert np.array_equal(core_nnls.nnls(a, b, maxiter=50 * a.shape[1]), expected)


def test_public_fallback_gives_the_same_answer(monkeypatch):
    monkeypatch.setattr(core_nnls, '_compiled_nnls', None)
    for a, b in _problems(1, 50):
        assert np.array_equal(core_nnls.nnls(a, b), scipy_nnls(a, b)[0])


def test_scaled_solution_is_optimal():
    """nnls_scaled: x >= 0 and the KKT conditions of the unscaled problem hold."""
    for a, b in _problems(2):
        x = core_nnls.nnls_scaled(a, b)
        assert np.all(x >= 0)
        grad = a.T @ (a @ x - b)
        tol = 1e-6 * (np.linalg.norm(a) * np.linalg.norm(b) + 1e-300)
        live = (x > 0) & (np.linalg.norm(a, axis=0) > 0)
        assert np.all(np.abs(grad[live]) <= tol)  # stationary where positive
        assert np.all(grad[x == 0] >= -tol)  # no descent into the feasible set


@pytest.mark.parametrize('solve', [core_nnls.nnls, core_nnls.nnls_scaled])
@pytest.mark.parametrize('bad', [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_refused(solve, bad):
    """Refuse NaN and inf, scaled or not: scipy's routine would return zeros without a word."""
    a = np.eye(3)
    a[2, 0] = bad
    with pytest.raises(ValueError, match='infs or NaNs'):
        solve(a, np.ones(3))
    with pytest.raises(ValueError, match='infs or NaNs'):
        solve(np.eye(3), np.array([1.0, bad, 0.0]))
