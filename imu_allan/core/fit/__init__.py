"""
The fit of noise terms to an Allan curve: the machinery per axis, the fitted model, its checks.

* :mod:`.axis`: the generalised least-squares fit of one axis (correlation between averaging
  times, IRLS weights, term selection, intervals, upper limits);
* :mod:`.tau_range`: the averaging times the sensor's own processing does not shape;
* :mod:`.adequacy`: does the fitted model describe the curve (a test with a calibrated p);
* :mod:`.hadamard_check`: the OHDEV curve decides a rate random walk against a rate ramp;
* :mod:`.fitted_model`: :func:`fit_noise_model` over every axis and its :class:`FittedModel`;
* :mod:`.advisor`: how much longer to record, from the fit's covariance forecast;
* :mod:`.nnls`, :mod:`.bounded_min`, :mod:`.bisection`: the solvers they share (non-negative
  least squares, a bounded 1-D minimum, guided bisection).
"""

from .adequacy import Adequacy, ADEQUACY_LEVEL, Misfit
from .axis import (
    ALTERNATIVE_MARGIN,
    AxisFit,
    coefficient_interval,
    correlation_matrix,
    CORRELATION_TAIL,
    CORRELATION_WIDTH,
    deterministic_index,
    fit_axis,
    fit_terms,
    FitError,
    Problem,
    problem_upper_limit,
    ramp_drift_variance,
    SELECTION_PENALTY,
    shape_columns,
    two_sided_z,
    upper_limit,
    UPPER_LIMIT_DELTA_CHI2,
    widen,
)
from .fitted_model import fit_noise_model, FittedModel
from .tau_range import Processing, TauRange

__all__ = ['Adequacy', 'ADEQUACY_LEVEL', 'ALTERNATIVE_MARGIN', 'AxisFit', 'coefficient_interval',
           'correlation_matrix', 'CORRELATION_TAIL', 'CORRELATION_WIDTH', 'deterministic_index',
           'fit_axis', 'fit_noise_model', 'fit_terms', 'FitError', 'FittedModel', 'Misfit',
           'Problem', 'problem_upper_limit', 'Processing', 'ramp_drift_variance',
           'SELECTION_PENALTY', 'shape_columns', 'TauRange', 'two_sided_z',
           'UPPER_LIMIT_DELTA_CHI2', 'upper_limit', 'widen']
