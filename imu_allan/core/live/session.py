"""
The allan node's computation behind one object: estimate, publish cycles, advice, budget state.

:class:`LiveSession` takes samples (:meth:`~LiveSession.feed`), runs a publish cycle in short
steps between message drains (:meth:`~LiveSession.start_cycle`, :meth:`~LiveSession.advance`)
and hands back a :class:`Publication` when one is done: the curves, the fitted model, the
upper limits of the terms not resolved and the per-sample variances for a republished stream.
The recording advice (:class:`~imu_allan.core.fit.advisor.StagedAdvice`) runs in the same
steps, at most every ``advice_period`` seconds.  It knows nothing of ROS: the node converts
messages to arrays, calls it and publishes; ``report/live_status.py`` words its state for
``/diagnostics``.

The options are the node's parameters by name (docs/interfaces.md, "allan parameters"):
:func:`pipeline_options` maps them to :class:`~imu_allan.core.live.online.OnlineAllan`'s, and
:func:`check_parameters` checks them as a whole.
"""

from dataclasses import dataclass
import math
import time

import numpy as np

from . import health as hm
from .change_monitor import ChangeMonitor
from .online import check_rate_options, OnlineAllan, StagedEstimate
from .streaming import parse_estimators
from ..allan.estimate import AllanResult
from ..fit.advisor import factor_grid_of, parse_targets, StagedAdvice
from ..fit.fitted_model import FittedModel
from ..model import ModelError, NoiseModel
from ..overbound import white_overbound
from ..temperature import TemperatureRange
from ..units import AXES, discrete_white_std, parse_terms
from ...errors import InputError

#: Fewest samples in a change-test window (its longest tau is a tenth of it).
CHANGE_MIN_SAMPLES = 100
#: Parameters whose change restarts the estimate (the new kinds' sums start with it too).
RESTART = frozenset({'rate_hz', 'window_s', 'max_tau', 'points_per_decade', 'stride_base',
                     'min_clusters', 'gate', 'gate_window_s', 'gate_std_factor',
                     'gate_step_factor', 'gate_gyro_max', 'gate_hold_s', 'gap_factor',
                     'estimators'})
_CHANGE = frozenset({'change_window_s', 'change_hold_s', 'change_reset'})


def pipeline_options(p):
    """Return :class:`OnlineAllan` keyword arguments from a parameter dictionary."""
    gate_options = {'window_s': p['gate_window_s'], 'std_factor': p['gate_std_factor'],
                    'step_factor': p['gate_step_factor'], 'gyro_max': p['gate_gyro_max'],
                    'hold_s': p['gate_hold_s']}
    return {'rate_hz': p['rate_hz'], 'gate': p['gate'], 'gap_factor': p['gap_factor'],
            'terms': parse_terms(p['terms'], 'terms'), 'gate_options': gate_options,
            'max_tau': p['max_tau'], 'points_per_decade': p['points_per_decade'],
            'stride_base': p['stride_base'], 'min_clusters': p['min_clusters'],
            'window_s': p['window_s'], 'filter_window_s': p['filter_window_s'],
            'estimators': parse_estimators(p['estimators'])}


def check_parameters(p):
    """Cross-field checks on a full parameter dictionary; raise InputError with the reason."""
    if p['rate_hz']:  # a measured rate is checked by OnlineAllan once it is known
        check_rate_options(p['rate_hz'], p['max_tau'], p['window_s'], p['min_clusters'],
                           p['gate_window_s'] if p['gate'] else None)
        if 0 < p['change_window_s'] * p['rate_hz'] < CHANGE_MIN_SAMPLES:
            raise InputError('change_window_s', f'too short: needs at least '
                                                f'{CHANGE_MIN_SAMPLES} samples')
    parse_terms(p['terms'], 'terms')
    parse_estimators(p['estimators'])
    parse_targets(p['targets'], 'targets')
    hm.NoiseBudget.from_yaml(p['budget_file'] or None)
    _load_model(p['model_file'])


def _load_model(path):
    """Return the reference noise model of ``model_file`` (None when empty)."""
    try:
        return NoiseModel.from_yaml(path) if path else None
    except ModelError as exc:
        raise InputError('model_file', str(exc)) from None


@dataclass
class Publication:
    """
    What one finished publish cycle publishes (SI throughout).

    ``fitted`` and ``variance`` are None until a fit exists; ``variance`` holds the
    per-sample variances N^2 f per axis for ``covariance_topic`` (NaN: keep the incoming
    message's).
    """

    result: AllanResult = None  # None: too little data for an estimate
    deviations: dict = None  # kind -> AllanResult of the other estimators (mdev, ohdev)
    fitted: FittedModel = None
    variance: np.ndarray = None


class LiveSession:
    """
    The live estimate of one IMU stream and everything computed on it, in bounded steps.

    ``params``: the allan node's parameters by name (validated by :func:`check_parameters`);
    ``log(level, text)``, level ``'info'`` or ``'warn'``: the sample rate once known and each
    change the change test finds.
    """

    def __init__(self, params, log=None):
        self.params = params
        self.log = log or (lambda level, text: None)
        self.budget = hm.NoiseBudget.from_yaml(params['budget_file'] or None)
        self.model = _load_model(params['model_file'])
        self.pipeline = OnlineAllan(axes=AXES, **pipeline_options(params))
        self.temperature = TemperatureRange(params['window_s'])
        self.change = None  # the change test, once the rate is known
        self.latest = None  # the last Publication
        self.advice = None  # the last finished recording advice (Advice), if any
        self.advice_note = None  # why there is none, when there cannot be one
        self.last_cycle = {'cycle_total_s': math.nan, 'cycle_max_step_s': math.nan,
                           'cycle_wall_s': math.nan}
        self._cycle = self._staged_advice = None
        self._advice_due = 0.0
        self._advice_samples = 0  # the record length of the last advice started

    def reconfigure(self, changed):
        """Apply the changed parameter names (``params`` already holds the new values)."""
        p = self.params
        if changed & RESTART:
            self.log('info', 'estimator settings changed: estimate restarted')
            self.pipeline = OnlineAllan(axes=AXES, **pipeline_options(p))
            self.temperature = TemperatureRange(p['window_s'])
            # A cycle of the old estimate is not finished: it would read the new pipeline
            # (its rate is None until measured: a TypeError, seen in tests).
            self._cycle = None
        elif 'terms' in changed:
            self.pipeline.terms = parse_terms(p['terms'], 'terms')
        if 'budget_file' in changed:
            self.budget = hm.NoiseBudget.from_yaml(p['budget_file'] or None)
        if 'model_file' in changed:
            self.model = _load_model(p['model_file'])
        if changed & (_CHANGE | RESTART):
            self.change = None
            self._start_change()  # a fresh baseline, OK until a new change

    # -- samples -----------------------------------------------------------------------

    def feed(self, t, data):
        """Feed stamps ``t`` (s) and samples ``(n, 6)`` (SI) to the estimate and change test."""
        started = self.pipeline.estimator is not None
        self.pipeline.feed(t, data)  # InputError when a measured rate misfits the options
        if not started and self.pipeline.estimator is not None:
            self.log('info', f'sample rate {self.pipeline.rate_hz:.6g} Hz '
                             f'({self.pipeline.rate_source}); estimator memory '
                             f'{self.pipeline.memory_bytes() / 1024:.0f} KiB (fixed)')
        self._start_change()
        if self.change is not None:
            for c in self.change.feed(t, data):
                self.log('warn', f'{c.axis}: {c.what} changed at stamp {c.t_s:.3f} s '
                                 f'(ratio {c.ratio:.3g})')

    def _start_change(self):
        """Start the change test once the sample rate is known (off at change_window_s 0)."""
        if self.change is None and self.params['change_window_s'] and self.pipeline.rate_hz:
            self.change = ChangeMonitor(self.pipeline.rate_hz, self.params['change_window_s'],
                                        AXES, self.params['change_hold_s'])

    # -- cycles ------------------------------------------------------------------------

    @property
    def busy(self):
        """Return True while a publish cycle or the advice has steps left."""
        return self._cycle is not None or self._staged_advice is not None

    def start_cycle(self):
        """Freeze the sums for a publish cycle; False if the previous one is still running."""
        if self._cycle is not None:
            return False
        self._cycle = StagedEstimate(self.pipeline, window=self.params['window_s'] > 0)
        self._cycle_cpu = self._cycle_max_step = 0.0
        self._cycle_wall = time.monotonic()
        return True

    def advance(self, budget_s):
        """
        Run cycle (else advice) steps for about ``budget_s`` seconds of CPU.

        Return the :class:`Publication` when this call finished a cycle, else None.
        """
        start = time.perf_counter()
        if self._cycle is None:
            if self._staged_advice is not None:
                self._advance_advice(start, budget_s)
            return None
        cycle = self._cycle
        while not cycle.done and time.perf_counter() - start < budget_s:
            t0 = time.perf_counter()
            cycle.step()
            self._cycle_max_step = max(self._cycle_max_step, time.perf_counter() - t0)
        self._cycle_cpu += time.perf_counter() - start
        if not cycle.done:
            return None
        self._cycle = None
        self.last_cycle = {'cycle_total_s': self._cycle_cpu,
                           'cycle_max_step_s': self._cycle_max_step,
                           'cycle_wall_s': time.monotonic() - self._cycle_wall}
        self.latest = self._publication(cycle)
        self._start_advice(cycle.result, cycle.fitted)
        return self.latest

    def _publication(self, cycle):
        pub = Publication(cycle.result, cycle.deviations, cycle.fitted)
        fitted = cycle.fitted
        if fitted is None:
            return pub
        # robot_localization reads per-message variances: N^2 f (NaN: keep the driver's)
        white = np.array([fitted.value(a, 'white_noise') for a in AXES])
        if self.params['covariance_mode'] == 'overbound' and cycle.result is not None:
            white = white_overbound(cycle.result, AXES)
        pub.variance = discrete_white_std(white, self.pipeline.rate_hz) ** 2
        return pub

    def _start_advice(self, result, fitted):
        """
        Start the recording advice on a finished estimate.

        At most every ``advice_period``, and also whenever the record has doubled since the
        last advice: a start-up's first advice (5 s of data) would otherwise stand for a
        minute beside estimates four times as precise.
        """
        now = time.monotonic()
        grown = result is not None and result.n_samples >= 2 * self._advice_samples
        if self._staged_advice is not None or fitted is None or (now < self._advice_due
                                                                 and not grown):
            return
        self._advice_due = now + self.params['advice_period']
        self._advice_samples = result.n_samples
        if self.params['window_s'] > 0:  # a sliding window does not grow with recording
            self.advice_note = 'no advice with a sliding window (window_s > 0)'
            return
        self.advice_note = None
        est = self.pipeline.estimator
        self._staged_advice = StagedAdvice(result, fitted, parse_targets(self.params['targets']),
                                           factor_grid_of(est.ms, est.min_clusters))

    def _advance_advice(self, start, budget_s):
        staged = self._staged_advice
        while not staged.step() and time.perf_counter() - start < budget_s:
            pass
        if staged.done:
            self.advice, self._staged_advice = staged.advice, None
