"""
The recording advice of ``analyze``: the ``advice`` JSON block and the closing sentence.

The advice itself is computed with the rest of the record
(:func:`imu_allan.core.record.record_advice`); this module renders it.

JSON (design.md section 6, key ``advice``)::

    {"targets": {"white_noise": 0.02, ...},
     "axes": {"gyro_x": {"white_noise": {"rel_halfwidth": x, "more_s": s}, ...}, ...},
     "unresolved": [{"axis": "accel_x", "terms": ["bias_instability", "rate_random_walk"],
                     "more_s": s}],
     "record_more_s": s,
     "undetected": [{"axis": ..., "term": ..., "upper_limit": u, "unit": ..., "more_s": s}]}

``more_s`` (s of additional recording at the same rate and conditions) is 0 when a target is
met and null only when no prediction is possible, with a ``reason`` beside it.  ``undetected``
(an extension) lists terms not detected: their 95 % upper limit (SI, continuous-time) and the
time after which a term that large would be detected.
"""

import math

from ..core.units import si_unit


def _num(value):
    return float(value) if value is not None and math.isfinite(value) else None


def _time_entry(entry, **extra):
    out = {**extra, 'more_s': _num(entry.more_s)}
    if entry.more_s is None and entry.reason:
        out['reason'] = entry.reason
    return out


def advice_to_json(advice):
    """Return the ``advice`` block (JSON-ready)."""
    axes, undetected = {}, []
    for axis, terms in advice.axes.items():
        axes[axis] = {}
        for term, entry in terms.items():
            if entry.detected:
                axes[axis][term] = _time_entry(entry, rel_halfwidth=_num(entry.rel_halfwidth))
            else:
                undetected.append(_time_entry(entry, axis=axis, term=term,
                                              upper_limit=_num(entry.upper_limit),
                                              unit=si_unit(axis, term)))
    return {'targets': dict(advice.targets), 'axes': axes,
            'unresolved': [_time_entry(u, axis=u.axis, terms=list(u.terms),
                                       **({} if u.alternative is None else
                                          {'alternative': list(u.alternative)}))
                           for u in advice.unresolved],
            'record_more_s': _num(advice.record_more_s),
            'undetected': undetected,
            'inadequate': list(advice.inadequate)}


def format_duration(seconds):
    """'about 40 s', 'about 25 min', 'about 1.5 h', 'about 3.2 days' (rounded for people)."""
    if seconds < 90:
        return f'about {max(seconds, 1.0):.0f} s'
    if seconds < 90 * 60:
        return f'about {seconds / 60:.0f} min'
    if seconds < 48 * 3600:
        return f'about {seconds / 3600:.2g} h'
    return f'about {seconds / 86400:.2g} days'


def term_words(term):
    """Return a term's name for people: 'white noise', 'Gauss-Markov'."""
    return 'Gauss-Markov' if term == 'gauss_markov' else term.replace('_', ' ')


def _percent(rel):
    return f'{100 * rel:.3g} %'


def alternative_words(u):
    """
    One unresolved alternative in words, with the time until the data decide.

    'gyro_x: rate random walk or rate ramp: cannot tell yet; record about 4 h more'.
    """
    if len(u.terms) == 2:
        what = f'{term_words(u.terms[0])} or {term_words(u.terms[1])}'
    elif len(u.terms) == 1:
        what = f'{term_words(u.terms[0])} or none'
    else:
        what = 'which of ' + ', '.join(term_words(t) for t in u.terms)
    if u.more_s:
        when = f'record {format_duration(u.more_s)} more'
    else:
        when = f'no record length within reach will tell ({u.reason})' if u.reason else \
            'record longer'
    return f'{u.axis}: {what}: cannot tell yet; {when}'


def advice_sentence(advice):
    """
    One sentence a person can act on: how much longer to record, and why.

    Never "no need to record longer" while an alternative term set remains open
    (``advice.unresolved``), the record was moving (``advice.moving``) or a model does not
    describe its curve (``advice.inadequate``: its precision is not precision).
    """
    moving = getattr(advice, 'moving', None)
    if moving:
        return (f'advice: the IMU moved during the record ({", ".join(moving)}): the curve '
                f'measures the motion, not the sensor noise; record again at rest (on a '
                f'still, vibration-free support) for the noise coefficients.')
    detected = [(axis, term, e) for axis, terms in advice.axes.items()
                for term, e in terms.items() if e.detected]
    record = advice.record_more_s
    clauses = []
    limiting = max(((e.more_s, term) for _, term, e in detected if e.more_s), default=None)
    pair_max = max((u.more_s for u in advice.unresolved if u.more_s), default=0.0)
    if limiting is not None and limiting[0] >= pair_max:
        term = limiting[1]
        axes = [a for a, t, _ in detected if t == term]  # package axis order
        where = 'on all axes' if len(axes) == len(advice.axes) else 'on ' + ', '.join(axes)
        clauses.append(f'record {format_duration(record)} more to pin {term_words(term)} to '
                       f'{_percent(advice.targets[term])} {where}')
    elif record > 0:
        clauses.append(f'record {format_duration(record)} more to tell the unresolved terms '
                       f'apart')
    clauses += [alternative_words(u) for u in advice.unresolved]
    inadequate = list(advice.inadequate)
    if inadequate:
        clauses.append(f'the noise model does not describe {", ".join(inadequate)}: their '
                       'precision figures are not meaningful (see the model check); a longer '
                       'record does not mend a model')
    for axis, term, e in detected:
        if e.more_s is None:
            clauses.append(f'{axis} {term_words(term)} will not reach '
                           f'{_percent(advice.targets[term])} ({e.reason})')
    if not clauses and not advice.unresolved and not inadequate:
        met = sorted({t for _, t, _ in detected})
        targets = ', '.join(f'{term_words(t)} {_percent(advice.targets[t])}' for t in met)
        return f'advice: every precision target is met ({targets}): no need to record longer.'
    return 'advice: ' + '; '.join(clauses) + '.'
