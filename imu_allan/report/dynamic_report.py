"""
``analyze --dynamic`` in report.json and on the console (the plots: :mod:`.dynamic_plots`).

``dynamic`` in report.json: ``window_s``, ``step_s``, ``false_alarm_rate_per_day`` (the figure
measured on simulated static data, per axis), ``target_false_alarms_per_day``, ``tau_s``,
``analysed_from_s`` (the warm-up left out, s) and ``changes`` (``axis``, ``t_s`` from the first
sample, ``what``, ``ratio``, ...).  Renders a :class:`~imu_allan.core.record.DynamicAnalysis`.
"""

from ..core.change.detection import (
    DEFAULT_TARGET_PER_DAY,
    MEASURED_AXIS_DAYS,
    MEASURED_FALSE_ALARMS_PER_DAY,
)


def dynamic_json(part):
    """Return the report.json ``dynamic`` block (SI; times from the first sample)."""
    dyn, changes = part.result, part.changes
    target = DEFAULT_TARGET_PER_DAY  # record.dynamic_analysis calls detect_changes(dyn)
    return {'window_s': float(dyn.window_s), 'step_s': float(dyn.step_s),
            'false_alarm_rate_per_day': MEASURED_FALSE_ALARMS_PER_DAY,
            'false_alarm_note': 'measured per axis per day on simulated static data (thesis '
                                '3DM-GX3-25 model + rate random walk, 100 Hz, default window): '
                                f'0 alarms in {MEASURED_AXIS_DAYS:g} axis-days, 95 % upper '
                                f'bound {3.0 / MEASURED_AXIS_DAYS:.2g}; the threshold targets '
                                f'{target:g} per axis per day',
            'target_false_alarms_per_day': float(target),
            'tau_s': [float(t) for t in dyn.tau],
            'analysed_from_s': float(part.analysed_from_s),
            'changes': [c.to_json() for c in changes]}


def dynamic_sentence(part):
    """Return the console line(s) of the change test."""
    dyn, changes = part.result, part.changes
    head = (f'dynamic Allan deviation: window {dyn.window_s:.4g} s, step {dyn.step_s:.4g} s; '
            f'{len(changes)} change(s)')
    lines = [head]
    for c in changes:
        lines.append(f'  {c.axis:8} {c.what:17} at {c.t_s:.1f} s, ratio {c.ratio:.3g}')
    return '\n'.join(lines)
