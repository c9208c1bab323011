"""
The discrepancy workflow: where do a noise model and measured data disagree, and why.

Given measured IMU samples and a starting noise model (a model file, or a few named terms fitted
to the data), the workflow

1. computes the measured overlapping Allan deviation (:func:`~imu_allan.core.allan.estimate.
   allan_deviation`);
2. builds, for every averaging time, where the measured log-deviation should lie if the model
   were complete: the analytic curve of the model (:mod:`imu_allan.core.terms`) corrected for the
   bias of the log of a chi-square estimate, with a spread from the model's equivalent degrees of
   freedom (Greenhall EDF of each term, :mod:`imu_allan.core.allan.edf`), pooled with ``n_sims``
   independent simulations of the model at the measured rate and length through the same
   estimator;
3. measures the gap per averaging time, z_i = (ln adev_meas - centre_i) / spread_i, and one
   number per axis, G = sqrt(mean_i z_i^2), which is about 1 when the model is complete; its
   significance uses the effective number of independent averaging times
   T_eff = T^2 / sum_ij rho_ij^2 (rho: the measured correlation of estimates between averaging
   times, :func:`~imu_allan.core.fit.correlation_matrix`), G^2 T_eff ~ chi-square(T_eff);
4. locates the band of averaging times where the data leave the model's band (smoothed |z| > 2
   around the largest excursion);
5. lets every effect the model lacks compete: each is added and all terms are refitted (a
   weighted least-squares fit in log-deviation, the same metric as the gap); with the effective
   Akaike criterion AIC = (T_eff / T) Q + 2 k (Q = sum z^2 after the fit, k parameters), the
   winner is the candidate whose AIC drop per added parameter is largest, and it is only
   accepted if its improvement is significant (a Satterthwaite chi-square test of Delta Q under
   the correlated null, Bonferroni over the candidates, and for Gauss-Markov / sinusoid also
   over the T_eff positions their hump could take);
6. adds it, refits, re-simulates, re-measures, and repeats until nothing significant is left.

A step that raises the gap is not kept (the next candidate gets its turn).

Several recordings of one configuration (any rates, any runs) are compared with the model they
state by :func:`find_discrepancies`: each term's factor (measured / stated) and how it scales
with the sample rate, its correlation time, whether it is there at all and is the process
stated, the turn-on bias across runs, the drift's sign, and the messages' covariance; each
disagreement is a :class:`Finding` of one class.

Everything is SI (rad/s, m/s^2, s, Hz) and ROS-free.  Modules: :mod:`.band` (steps 2-4),
:mod:`.significance` (the tests of step 5, whose fit is :func:`imu_allan.core.fit.fit_terms` on
:meth:`.band.Band.problem`), :mod:`.workflow` (steps 1, 5, 6 and the online summary);
:mod:`.evidence` (one recording against a stated model), :mod:`.pooling` (factors over
recordings and rates), :mod:`.runs` (turn-on bias and drift across runs), :mod:`.findings`
(the classes and the decision).  ``docs/discrepancy.md`` explains the method and the
validation results.
"""

from .band import ALPHA, Band, excursion_band, Gap, measure_gap, model_band, pool_simulations
from .evidence import Recording
from .findings import find_discrepancies, Finding, FindingsResult
from .significance import improvement_test, satterthwaite
from .workflow import (
    Candidate,
    DEFAULT_START,
    DiscrepancyResult,
    evaluate_candidates,
    gap_summary,
    run_discrepancy,
    run_samples,
    sample_rate,
    start_model,
    Step,
)

__all__ = ['ALPHA', 'Band', 'Candidate', 'DEFAULT_START', 'DiscrepancyResult',
           'evaluate_candidates', 'excursion_band', 'find_discrepancies', 'Finding',
           'FindingsResult', 'Gap', 'gap_summary', 'improvement_test', 'measure_gap',
           'model_band', 'pool_simulations', 'Recording', 'run_discrepancy', 'run_samples',
           'sample_rate', 'satterthwaite', 'start_model', 'Step']
