"""
Is a drop in Q = sum z^2 significant when the z correlate (the discrepancy's tests).

The discrepancy fit is working-independence (:meth:`imu_allan.core.fit.Problem.from_log_level`):
under the null (the smaller model is complete) z ~ N(0, R) with R the estimates' correlation,
and the drop in Q when columns are added is a quadratic form z' P z, matched here by
c chi-square(h) (Satterthwaite).
"""

import numpy as np
from scipy.stats import chi2


def satterthwaite(jac_nuisance, jac_added, corr):
    """
    Satterthwaite match c chi-square(h) of the drop in sum z^2 when ``jac_added`` is added.

    Under the null z ~ N(0, R), the drop is z' P z with P the projection on the added
    directions orthogonal to the nuisance ones (``jac_nuisance``: None or no columns for
    none); c = tr(PRPR) / tr(PR), h = tr(PR)^2 / tr(PRPR).  Returns ``(c, h)``, or None when
    the added directions vanish or a trace is not positive.
    """
    x = jac_added
    if jac_nuisance is not None and jac_nuisance.size:
        x = x - jac_nuisance @ (np.linalg.pinv(jac_nuisance) @ x)
    if not np.any(np.abs(x) > 0):
        return None
    proj = x @ np.linalg.pinv(x)
    pr = proj @ corr
    e = float(np.trace(pr))
    v = float(np.sum(pr * pr.T))
    if e <= 0 or v <= 0:
        return None
    return v / e, e * e / v


def improvement_test(delta_q, jac_nuisance, jac_added, corr):
    """
    p-value of a drop ``delta_q`` in sum z^2 when columns ``jac_added`` are added.

    Under the null (the smaller model is complete) the drop is matched by c chi-square(h)
    (:func:`satterthwaite`).  Returns ``(p, h)``.
    """
    if delta_q <= 0:
        return 1.0, 0.0
    match = satterthwaite(jac_nuisance, jac_added, corr)
    if match is None:
        return 1.0, 0.0
    c, h = match
    return float(chi2.sf(delta_q / c, h)), h
