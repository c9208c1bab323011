"""
The overlapping Allan estimator and its intervals.

* :mod:`.estimate`: the overlapping Allan variance of a record, its averaging-time grid and
  noise identification, the result with 68.3 % intervals (:func:`.estimate.allan_deviation`);
* :mod:`.kernel`: the compiled (numba) AVAR pass the estimator uses, tested against its numpy
  reference;
* :mod:`.edf`: Greenhall & Riley's equivalent degrees of freedom and the chi-square intervals.
"""
