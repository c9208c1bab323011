"""
The recording advice in words and in JSON: the one renderer of the console, page and node.

The advice is computed in core (:mod:`imu_allan.core.fit.advisor`): per axis the precision of
each resolved term, the open term sets and when they are told apart, the upper limit of each
term not resolved and when it would be.  :func:`advice_to_json` makes it data (report.json's
``advice`` block); everything a person reads is rendered from that data here, once: the
console's closing sentence (:func:`advice_sentence`), the page's headline and lines
(:func:`advice_headline`, :func:`axis_lines`), the allan node's ``/diagnostics`` statuses,
whose messages the ``monitor`` shows as they are (:func:`advice_statuses`).

The JSON schema and the meaning of each key (``more_s``: s of additional recording at the same
rate and conditions, 0 when a target is met, null with a ``reason`` when no prediction is
possible) are in docs/interfaces.md (``analyze --json`` key ``advice``).
"""

import math

from ..core.units import conventional, si_unit

#: Why two terms are hard to tell apart, in words (either order).
_WHY = {
    frozenset(('bias_instability', 'rate_random_walk')): 'both lift the longest averaging times',
    frozenset(('rate_random_walk', 'rate_ramp')): 'both rise at the longest averaging times, '
                                                  'a half-decade slope apart',
    frozenset(('bias_instability', 'rate_ramp')): 'both lift the longest averaging times',
    frozenset(('gauss_markov', 'bias_instability')): 'a hump and a floor look alike over '
                                                     'one decade',
}
#: The terms that show at the longest averaging times (any of them lifts the curve there).
_LONG_TAU = {'bias_instability', 'rate_random_walk', 'rate_ramp'}
#: Why a term may or may not be there, in words.
_MAYBE = {'quantization': 'the shortest averaging times do not yet show it apart from white '
                          'noise',
          'bias_instability': 'the curve has not yet flattened clearly',
          'rate_random_walk': 'the curve does not yet rise clearly at its end',
          'rate_ramp': 'the curve does not yet rise clearly at its end',
          'gauss_markov': 'the curve does not yet show a clear hump'}


def _num(value):
    return float(value) if value is not None and math.isfinite(value) else None


def _time_entry(entry, **extra):
    out = {**extra, 'more_s': _num(entry.more_s)}
    if entry.more_s is None and entry.reason:
        out['reason'] = entry.reason
    return out


def advice_to_json(advice):
    """Return the ``advice`` block (JSON-ready, strict: no NaN)."""
    undetected = [_time_entry(lim, axis=axis, term=term, upper_limit=_num(lim.upper_limit),
                              unit=si_unit(axis, term), open=bool(lim.in_open_set))
                  for axis, limits in advice.limits.items() for term, lim in limits.items()]
    return {'targets': dict(advice.targets),
            'axes': {axis: {term: _time_entry(e, rel_halfwidth=_num(e.rel_halfwidth))
                            for term, e in terms.items()}
                     for axis, terms in advice.axes.items()},
            'unresolved': [_time_entry(u, axis=u.axis, terms=list(u.terms),
                                       sets=[list(s) for s in u.sets])
                           for u in advice.unresolved],
            'record_more_s': _num(advice.record_more_s),
            'undetected': undetected,
            'inadequate': list(advice.inadequate),
            'moving': list(advice.moving)}


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
    return 'Gauss-Markov' if term == 'gauss_markov' else str(term).replace('_', ' ')


def _percent(rel):
    return f'{100 * rel:.3g} %'


def _when(entry, what='decides'):
    """'about 3 h more decides', or why no record length within reach does."""
    more = entry.get('more_s')
    if more:
        return f'{format_duration(more)} more {what}'
    if more == 0:
        return 'decided'
    return f'no record within reach {what} ({entry["reason"]})' if entry.get('reason') else \
        'a longer record is needed'


def open_sets_words(entry):
    """
    Say an axis's open term sets in one sentence: which terms, why they stay apart, how long.

    'cannot tell yet whether bias instability or rate random walk is there (both lift the
    longest averaging times); about 3 h more decides'.
    """
    sets = [set(s) for s in entry.get('sets') or []]
    differ = list(entry['terms'])
    common = set.intersection(*sets) if sets else set()
    pairs = [frozenset(p) for p in _WHY if p <= set(differ)]
    if len(differ) == 2 and pairs:
        what = f'{term_words(differ[0])} or {term_words(differ[1])}'
        why = _WHY[pairs[0]]
    elif len(differ) == 1:
        what = f'{term_words(differ[0])} or none'
        why = _MAYBE.get(differ[0], 'the curve does not yet tell')
    else:
        what = ('which of ' + ', '.join(term_words(t) for t in differ[:-1])
                + f' or {term_words(differ[-1])}')
        # one reason, said of all of them ("both" is for two)
        why = ('they all lift the longest averaging times' if set(differ) <= _LONG_TAU else
               '; '.join(dict.fromkeys(_WHY[p].replace('both', 'they') for p in pairs))
               or 'the curve does not yet tell')
    beside = (' beside ' + ', '.join(term_words(t) for t in sorted(common))) if common else ''
    # Fitted at near-zero sizes, open sets of a short record may never separate: the terms'
    # upper limits then say when each would be resolved if that large.
    when = (_when(entry) if entry.get('more_s') is not None or not entry.get('reason') else
            'no record within reach decides at their fitted sizes (see each term at its '
            'limit)')
    return f'cannot tell yet {what}{beside} ({why}); {when}'


def axis_lines(doc):
    """
    ``{axis: sentence}``: each axis's advice in one sentence, from the JSON ``advice`` block.

    The precision of every resolved term against its target, the open term sets once, and
    each term not resolved as its upper limit with the time until it is.
    """
    targets = doc.get('targets', {})
    out = {}
    unresolved = {u['axis']: u for u in doc.get('unresolved', [])}
    limits = {}
    for entry in doc.get('undetected', []):
        limits.setdefault(entry['axis'], []).append(entry)
    for axis in sorted(set(doc.get('axes', {})) | set(unresolved) | set(limits),
                       key=_axis_order(doc)):
        clauses = []
        for term, e in doc.get('axes', {}).get(axis, {}).items():
            rel = e.get('rel_halfwidth')
            head = term_words(term) + (f' ±{_percent(rel)}' if rel is not None else '')
            target = targets.get(term)
            if e.get('more_s') == 0:
                clauses.append(head + (f' (target {_percent(target)} met)' if target else ''))
            else:
                clauses.append(f'{head} (target {_percent(target)}: '
                               f'{_when(e, "reaches it")})' if target else head)
        if axis in unresolved:
            clauses.append(open_sets_words(unresolved[axis]))
        clauses += [w for w in (_limit_words(axis, e) for e in limits.get(axis, [])) if w]
        out[axis] = f'{axis}: ' + '; '.join(clauses)
    return out


def _axis_order(doc):
    axes = list(doc.get('axes', {}))
    return lambda a: (axes.index(a) if a in axes else len(axes), a)


def _limit_words(axis, entry):
    """'bias instability < 40 deg/h (95 %), resolved after about 20 min more if that large'."""
    limit = entry.get('upper_limit')
    name = term_words(entry['term'])
    if limit is None:  # nothing to say: the fit leaves it out here (quantization beside a filter)
        return None
    value, unit = conventional(axis, entry['term'], limit)
    head = f'{name} < {value:.3g} {unit} (95 %)'
    more = entry.get('more_s')
    if more:
        return f'{head}, resolved after {format_duration(more)} more if that large'
    return head if more == 0 else f'{head}, {_when(entry, "resolves it")}'


def advice_sentence(doc):
    """
    Return the console's closing sentence: how much longer to record, and why.

    Never "no need to record longer" while a term set remains open, the record was moving or
    a model does not describe its curve (its precision is not precision).
    """
    headline = advice_headline(doc)
    lines = list(axis_lines(doc).values())
    return 'advice: ' + headline + (' ' + ' '.join(line + '.' for line in lines)
                                    if lines and doc.get('moving') in (None, []) else '')


def advice_headline(doc, alternatives=False):
    """
    One sentence for the whole record, from the JSON ``advice`` block.

    ``alternatives``: the fit lists term sets the advice did not (an older report).
    """
    moving = doc.get('moving') or []
    if moving:
        return (f'the IMU moved during the record ({", ".join(moving)}): the curve measures '
                'the motion, not the sensor noise; record again at rest (on a still, '
                'vibration-free support) for the noise coefficients.')
    inadequate = doc.get('inadequate') or []
    more = doc.get('record_more_s')
    unmet = [(a, t) for a, terms in doc.get('axes', {}).items() for t, e in terms.items()
             if e.get('more_s') is None]
    open_sets = bool(doc.get('unresolved')) or alternatives
    if inadequate:
        tail = (f'the noise model does not describe {", ".join(inadequate)}: their precision '
                'figures are not meaningful (see the model check); a longer record does not '
                'mend a model.')
        return (f'record {format_duration(more)} more; ' if more else '') + tail
    if more:
        goal = ('meet every precision target and tell the open term sets apart'
                if open_sets else 'meet every precision target')
        return f'record {format_duration(more)} more (same rate and conditions) to {goal}.'
    if unmet:
        return 'some targets are out of reach of a longer record (below).'
    if open_sets:
        return ('every precision target is met, but the data cannot yet tell some term sets '
                'apart (below).')
    met = sorted({t for terms in doc.get('axes', {}).values() for t in terms})
    targets = ', '.join(f'{term_words(t)} {_percent(doc["targets"][t])}' for t in met
                        if t in doc.get('targets', {}))
    return f'every precision target is met ({targets}): no need to record longer.'


def advice_statuses(advice, name, prefix=''):
    """
    Return the allan node's ``/diagnostics`` statuses of the advice: record, then axes.

    ``advice``: an :class:`~imu_allan.core.fit.advisor.Advice` or None (STALE: no estimate
    yet); ``name``: the record status's name; per axis ``<prefix><axis> advice`` with its
    sentence (:func:`axis_lines`).  OK when every target is met and nothing is open, WARN
    otherwise.  The key-values are those of docs/interfaces.md (``/diagnostics``).
    """
    from ..core.live.health import Health, OK, STALE, WARN
    if advice is None:
        return [Health(name, STALE, 'no estimate yet (collecting still samples)', {})]
    doc = advice_to_json(advice)
    more = doc['record_more_s']
    headline = advice_headline(doc)
    settled = not more and not doc['unresolved'] and not doc['inadequate'] and not any(
        e.get('more_s') is None for terms in doc['axes'].values() for e in terms.values())
    out = [Health(name, OK if settled else WARN, headline,
                  {'record_more_s': _nan(more), 'recorded_s': advice.duration_s})]
    lines = axis_lines(doc)
    for axis, line in lines.items():
        values = {f'{t}.rel_halfwidth': _nan(e.get('rel_halfwidth'))
                  for t, e in doc['axes'].get(axis, {}).items()}
        values.update({f'{t}.more_s': _nan(e.get('more_s'))
                       for t, e in doc['axes'].get(axis, {}).items()})
        for entry in doc['undetected']:
            if entry['axis'] == axis:
                values[f'{entry["term"]}.upper_limit'] = _nan(entry['upper_limit'])
                values[f'{entry["term"]}.resolve_s'] = _nan(entry['more_s'])
        open_axis = any(u['axis'] == axis for u in doc['unresolved'])
        level = WARN if open_axis or any(e.get('more_s') != 0 for e in
                                         doc['axes'].get(axis, {}).values()) else OK
        out.append(Health(f'{prefix}{axis} advice', level, line[len(axis) + 2:], values))
    return out


def _nan(value):
    return math.nan if value is None else value
