"""
Non-negative least squares, min ||A x - b||_2 subject to x >= 0, for the noise fits.

The method is Lawson & Hanson's (1974), "Solving Least Squares Problems", ch. 23, as compiled
in scipy.  The fits solve thousands of these problems of at most seven columns (IRLS steps,
parameter profiles, the recording advisor's forecasts), and ``scipy.optimize.nnls`` spends
about 29 us checking its arguments around a solve of about 6 us.  :func:`nnls` checks only
what matters here (finite input: scipy's routine returns zeros for NaN without a word) and
calls the compiled routine directly when the installed scipy has it, loaded without the
0.3 s import of ``scipy.optimize`` (:mod:`..scipy_compiled`), the public function otherwise; a
test compares the two.
"""

import numpy as np

from ..scipy_compiled import extension

_compiled_nnls = getattr(extension('optimize', '_slsqplib'), 'nnls', None)


def nnls(a, b, maxiter=None):
    """
    Return x >= 0 minimising ||a x - b||_2 (a: (m, k), b: (m,), finite).

    ``maxiter`` bounds the active-set iterations (default 3 k, scipy's).  Raises ValueError
    for non-finite input and RuntimeError when the iterations run out, as scipy's does.
    """
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    maxiter = maxiter or 3 * a.shape[1]
    if _compiled_nnls is None:  # another scipy layout: the public function, checks and all
        from scipy.optimize import nnls as public_nnls
        return public_nnls(a, b, maxiter=maxiter)[0]
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        raise ValueError('array must not contain infs or NaNs')
    x, _, info = _compiled_nnls(a, b, maxiter)
    if info == 3:
        raise RuntimeError('Maximum number of iterations reached.')
    return x


def nnls_scaled(a, b):
    """
    :func:`nnls` with the columns of ``a`` scaled to unit norm for the solve.

    The term shapes span many decades; unscaled, the active-set method can run out of
    iterations on smooth curves (seen on the advisor's forecast grids), so every fit here
    solves the scaled problem, with 50 iterations per column, and scales back.
    """
    scale = np.sqrt(np.einsum('ij,ij->j', a, a))
    scale[scale == 0] = 1.0
    with np.errstate(invalid='ignore'):  # inf / inf: non-finite input, refused by nnls
        scaled = a / scale
    return nnls(scaled, b, maxiter=50 * a.shape[1]) / scale
