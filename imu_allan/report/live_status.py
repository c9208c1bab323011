"""
The allan node's ``/diagnostics`` records, worded from its session's state.

The session is a :class:`~imu_allan.core.live.session.LiveSession`.  In this order: the stream
(rate, gaps, samples used and dropped, the estimator's memory and the last cycle's cost), each
axis against the noise budget (resolved terms only; upper limits as notes), each axis's model
adequacy, the recording advice (record and per axis), the change test and, with a reference
model, the model-vs-data discrepancy.  The words are the ones ``analyze`` and ``monitor``
print: :mod:`.advice` and :mod:`.fit_quality` write them once.
"""

import math

from .advice import advice_statuses
from .coeffs_layout import alarm_lows, coefficient_table, limit_values
from .fit_quality import adequacy_health
from ..core.live import health as hm
from ..core.live.streaming import parse_estimators
from ..core.units import AXES, IEEE_TERMS


def session_records(session, silence_s, prefix, extra=None):
    """
    Return the :class:`~imu_allan.core.live.health.Health` records of a live session.

    ``silence_s``: seconds since the last message (inf before the first); ``prefix``: the
    node's name and a colon, the start of every status name; ``extra``: more key-values for
    the stream record (the figure publisher's counts).
    """
    p, params = session.pipeline, session.params
    latest = session.latest
    result = latest.result if latest is not None else None
    fitted = latest.fitted if latest is not None else None
    stream = p.stream_health(silence_s, params['timeout_s'], params['rate_tolerance'],
                             name=prefix + 'IMU stream')
    est = p.estimator
    stream.values.update({
        'samples_used': est.n_used if est else 0,  # on at least one axis
        'samples_offered': est.n_offered if est else 0,
        'averaging_times': 0 if result is None else int(result.tau.size),
        'longest_tau_s': math.nan if result is None else float(result.tau[-1]),
        'estimator_memory_bytes': p.memory_bytes(),
        'estimators': ','.join(parse_estimators(params['estimators'])),
        'window_s': params['window_s'],
        'budget_file': session.budget.source,
        'model_file': params['model_file'] or '(none)',
        **session.last_cycle,
        **(extra or {}),
        **session.temperature.key_values(),
    })
    if est is not None:  # per axis where values were rejected (NaN, inf, ...)
        stream.values.update({f'samples_used.{a}': int(n) for a, n, r in zip(
            p.axes, est.n_used_axes, p.rejected_total) if r})
    table = coefficient_table(fitted, AXES) if fitted is not None else None
    limits = (limit_values(fitted, AXES).reshape(len(AXES), len(IEEE_TERMS))
              if fitted is not None else None)
    records = [stream] + hm.budget_health(table, session.budget, AXES, prefix, limits,
                                          alarm_lows(fitted, AXES))
    records += adequacy_health(fitted, AXES, prefix)
    name = f'{prefix}recording advice'
    if session.advice_note is not None:
        records.append(hm.Health(name, hm.OK, session.advice_note))
    else:
        records += advice_statuses(session.advice, name, prefix)
    if session.change is not None:
        records += session.change.health(prefix)
    if session.model is not None:  # the discrepancy check: gap and effect per axis
        records += hm.discrepancy_health(session.model, result, AXES, prefix)
    return records
