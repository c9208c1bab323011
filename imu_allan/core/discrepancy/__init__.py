"""
The discrepancy workflow: where do a noise model and measured data disagree, and why.

From measured IMU samples and a starting model (a model file, or a few terms fitted to the
data) the workflow measures the overlapping Allan deviation, builds the band where the log-
deviation should lie if the model were complete (analytic centre and EDF spread, pooled with
simulations), measures the gap z_i = (ln adev_meas - centre_i) / spread_i and
G = sqrt(mean_i z_i^2) (G^2 T_eff ~ chi-square(T_eff), T_eff = T^2 / sum_ij rho_ij^2), and
lets every effect the model lacks compete (effective AIC gain per parameter, accepted when a
Satterthwaite test is significant after Bonferroni), adding the winner until nothing
significant is left; a step that raises the gap is not kept.  docs/discrepancy.md sections
2-4 give the method.

Several recordings of one configuration (any rates, any runs) are compared with the model they
state by :func:`find_discrepancies`: each disagreement is a :class:`Finding` of one class
(docs/discrepancy.md section 8).

Everything is SI (rad/s, m/s^2, s, Hz) and ROS-free.  Modules: :mod:`.band` (band and gap),
:mod:`.significance` (the tests), :mod:`.workflow` (the search and the online summary);
:mod:`.evidence` (one recording against a stated model), :mod:`.pooling` (factors over
recordings and rates), :mod:`.runs` (turn-on bias and drift across runs), :mod:`.findings`
(the classes and the decision).
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
    sample_rate,
    start_model,
    Step,
)

__all__ = ['ALPHA', 'Band', 'Candidate', 'DEFAULT_START', 'DiscrepancyResult',
           'evaluate_candidates', 'excursion_band', 'find_discrepancies', 'Finding',
           'FindingsResult', 'Gap', 'gap_summary', 'improvement_test', 'measure_gap',
           'model_band', 'pool_simulations', 'Recording', 'run_discrepancy',
           'sample_rate', 'satterthwaite', 'start_model', 'Step']
