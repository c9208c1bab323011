"""
Which findings matter: a factor must leave a band the user cares about, not only exclude 1.

A finding of a class in :data:`RATIO_CLASSES` (``run_to_run``: :data:`RATIO_KINDS` only) is
*material* only when its factor lies outside the band [lo, hi] (default 0.8-1.25; squared for
:data:`VARIANCE_CLASSES`) at some recorded rate: a factor that scales with the rate is judged at
each recorded rate.  Below it the finding is kept aside as *consistent within X %*, X the
farthest end of its 95 % interval from 1.  Every other class is a different process, not a
size, and always material.  docs/discrepancy.md section 8 ("Materiality") gives the reasons.
"""

from dataclasses import dataclass
import math

from .band import Z95

#: The default band of factors that do not matter (a 20 % smaller or 25 % larger value).
DEFAULT_BAND = (0.8, 1.25)
#: Classes whose factor is a ratio, 1 as stated (``run_to_run``: the kinds below only).
RATIO_CLASSES = ('white_scale', 'bias_scale', 'time_constant', 'metadata', 'run_to_run')
#: The run-to-run kinds whose factor is a ratio (a sign agreement is not).
RATIO_KINDS = ('spread', 'mean', 'decay')
#: Classes whose factor is a ratio of variances: the band squared.
VARIANCE_CLASSES = ('metadata',)


@dataclass(frozen=True)
class Materiality:
    """The band [lo, hi] of scale factors that do not matter (lo <= 1 <= hi, lo > 0)."""

    lo: float = DEFAULT_BAND[0]
    hi: float = DEFAULT_BAND[1]

    def __post_init__(self):
        """Refuse a band that does not hold 1 or is not positive."""
        if not (0.0 < self.lo <= 1.0 <= self.hi and math.isfinite(self.hi)):
            raise ValueError(f'the band {self.lo:g}-{self.hi:g} must hold 1 (0 < lo <= 1 <= hi)')

    def applies(self, finding):
        """Return True when the finding's factor is a ratio the band judges."""
        if finding.cls not in RATIO_CLASSES or finding.factor is None:
            return False
        return finding.cls != 'run_to_run' or finding.evidence.get('kind') in RATIO_KINDS

    def band_of(self, finding):
        """Return the band for this finding's factor: squared for a ratio of variances."""
        power = 2 if finding.cls in VARIANCE_CLASSES else 1
        return self.lo ** power, self.hi ** power

    @staticmethod
    def _at_rates(finding):
        """``[(factor, ln-space 95 % half-width or None)]`` at each recorded rate."""
        per_rate = finding.evidence.get('per_rate')
        if finding.rate_exponent is not None and per_rate:
            return [(r['factor'], Z95 * math.log(r['factor_ci'][1] / r['factor']))
                    for r in per_rate if r['factor'] > 0]
        return [(finding.factor, None)]

    def material(self, finding):
        """Return True when the finding matters: always, or a factor outside the band."""
        if not self.applies(finding):
            return True
        lo, hi = self.band_of(finding)
        return any(not lo <= f <= hi for f, _ in self._at_rates(finding))

    def within_percent(self, finding):
        """
        Return X: the farthest end of the finding's 95 % interval from 1, in % (at its rates).

        ``factor_ci95`` without a rate exponent; with one, each rate's factor widened to 95 %.
        """
        ends = []
        for factor, half in self._at_rates(finding):
            if half is not None:
                ends += [factor * math.exp(-half), factor * math.exp(half)]
            elif finding.factor_ci95:
                ends += list(finding.factor_ci95)
            else:
                ends.append(factor)
        return 100.0 * max(abs(e - 1.0) for e in ends)

    def to_dict(self):
        """Return the band as the report states it."""
        return {'scale': [self.lo, self.hi], 'variance': [self.lo ** 2, self.hi ** 2],
                'classes': list(RATIO_CLASSES), 'run_to_run_kinds': list(RATIO_KINDS),
                'rule': 'a finding of these classes is material only when its factor lies '
                        'outside the band at some recorded rate; below it: consistent within '
                        'X %, X the farthest end of its 95 % interval from 1'}
