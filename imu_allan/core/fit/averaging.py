"""
Intervals that carry the choice of terms: model averaging over the candidate term sets.

Each candidate set S (less those another curve rejected) gets the Akaike weight
w_S = exp(-(crit_S - crit_best) / 2) / sum, crit_S = chi^2_S + 2 k_S (Buckland, Burnham &
Augustin 1997, Biometrics 53, 603), and its fit a confidence distribution for the squared
coefficient c: the one its own interval inverts (:func:`.axis.coefficient_interval`), a point
mass at zero where S lacks the term.  The interval is the mixture's quantiles, the
model-averaged tail-area interval of Turek & Fletcher (2012, CSDA 56, 2809).  Why and how well:
docs/method.md section 11.
"""

import math

import numpy as np

from .axis import ALTERNATIVE_MARGIN, chi_square_applies
from .bisection import halve
from ..scipy_compiled import function

_gammaincc = function('special', '_special_ufuncs', 'gammaincc')
_erf = function('special', '_special_ufuncs', 'erf')
#: Sets whose weight is below this share of the largest are left out (exp(-23): nothing the
#: quantiles can see).
_NEGLIGIBLE = 1e-10
_BISECTIONS = 80
#: Criterion charge per term of the weights: 2, Akaike's (the selection's own 2 ln T per term
#: would put nearly all weight on the selected set and give back its selection-blind width).
AVERAGING_PENALTY = 2.0


def weights(fit):
    """
    Return ``[(weight, AxisFit), ...]``: every candidate set's fit of ``fit`` with its weight.

    Sets another curve contradicts are left out.  A fit without candidates (named terms, a
    remedy's set) is the one set, weight 1.
    """
    scored = []
    rejected = fit.rejected_sets
    for _, names in fit.candidates:
        key = frozenset(names)
        if key in fit.candidate_fits and key not in rejected:
            f = fit.candidate_fits[key]
            scored.append((f.chi2 + AVERAGING_PENALTY * len(f.terms), f))
    if not scored:
        return [(1.0, fit)]
    best = min(crit for crit, _ in scored)
    out = [(math.exp(-0.5 * (crit - best)), f) for crit, f in scored]
    out = [(w, f) for w, f in out if w > _NEGLIGIBLE]
    total = sum(w for w, _ in out)
    return [(w / total, f) for w, f in out]


def _cdf(fit, term, scale):
    """
    Confidence distribution of a squared coefficient under one set's fit, or None: absent.

    P(c <= x) (array x): the probability, were c = x, of an estimate above the one found,
    under the distribution the set's own interval inverts (:func:`.axis.coefficient_interval`).
    """
    if term not in fit.coef:
        return None
    j = list(fit.coef).index(term)
    c = fit.coef[term]
    var = max(float(fit.cov[j, j]), 0.0) * scale * scale
    if not (var > 0 and c > 0):
        return lambda x: (np.asarray(x) >= c).astype(float)
    nu = 2.0 * c * c / var
    # the choice coefficient_interval makes (at 95 %): chi-square unless it is so skewed that
    # its quantiles misbehave; there, and for the ramp, normal
    if term == 'rate_ramp' or not chi_square_applies(c, var, 0.95):
        sd = math.sqrt(var)
        return lambda x: 0.5 * (1.0 + _erf((np.asarray(x) - c) / (sd * math.sqrt(2.0))))
    return lambda x: _gammaincc(0.5 * nu, 0.5 * nu * c / np.maximum(np.asarray(x), 1e-300))


def selection_gain(fit, term):
    """
    ``(G, G*)``: the chi^2 gain that resolved a term, and the gain that would just have.

    The term is resolved because the best of the selected set's subsets without it (none
    another curve rejected) trails the selected set by D >= :data:`.axis.ALTERNATIVE_MARGIN` in
    the criterion chi^2 + k ``fit.selection_penalty``: a chi^2 gain G = D + (k_sel - k_without)
    penalty, G* the same at D = the margin.  (A set that swaps the term for another is a
    question of which term, not of how large: the weights of :func:`weights` carry it.)  None
    for white noise (in every set), a term the selection did not choose, or no such subset.
    """
    if term == 'white_noise' or not fit.candidate_fits or term not in fit.coef:
        return None
    chosen, rejected = set(fit.terms), fit.rejected_sets
    for crit, names in fit.candidates:
        if term not in names and set(names) < chosen and frozenset(names) not in rejected:
            extra = (len(fit.terms) - len(names)) * fit.selection_penalty
            return crit - fit.candidates[0][0] + extra, ALTERNATIVE_MARGIN + extra
    return None


def selective_lower(c, gain, needed, level):
    """
    Lower end of a resolved term's ``level`` interval given that it was resolved (SI^2, c).

    Near the null the gain grows as the squared estimate, G = (c_hat / s)^2, so the estimate
    has the standard deviation s = c_hat / sqrt(G) it is measured against, and the term is
    reported when c_hat exceeds k = s sqrt(G*).  Given that, c_hat is a normal variable of
    mean c truncated at k (Lee, Sun, Sun & Taylor 2016, "Exact post-selection inference",
    Ann. Stat. 44, 907, for one selected coordinate): the lower end solves
    P(c_hat' > c_hat | c_hat' > k; c) = p, i.e. Phi((x - c_hat) / s) / Phi((x - k) / s) = p.
    Just past the threshold it reaches 0: such a term was reported because it came out high.
    """
    if not (gain > 0 and c > 0):
        return 0.0
    p = 0.5 * (1.0 - level)
    s = c / math.sqrt(gain)
    k = s * math.sqrt(max(needed, 0.0))

    def tail(x):  # P(c_hat' > c_hat | c_hat' > k; c = x)
        num = 0.5 * (1.0 + float(_erf((x - c) / (s * math.sqrt(2.0)))))
        den = 0.5 * (1.0 + float(_erf((x - k) / (s * math.sqrt(2.0)))))
        return num / den if den > 1e-300 else 0.0
    if tail(0.0) >= p:
        return 0.0
    return halve(lambda x: tail(x) < p, 0.0, c, _BISECTIONS, 1e-9 * c)  # tail grows with x


def averaged_interval(weighted, term, level, selected=None, scale=1.0, selection=None):
    """
    Two-sided ``level`` interval of a term's main parameter sqrt(c) over weighted set fits.

    ``weighted``: :func:`weights`; ``scale``: a factor on the standard deviation of every set
    but ``selected`` (the adequacy test's Birge ratio, already in the selected fit's
    covariance); ``selection``: :func:`selection_gain` of a term the selection resolved, whose
    lower end then also reaches :func:`selective_lower` (the upper end is the averaged one:
    the winner's curse biases a term reported near its threshold upwards).  Returns
    ``(lo, hi)`` (SI).
    """
    p = 0.5 * (1.0 - level)
    parts = [(w, _cdf(f, term, 1.0 if f is selected else scale)) for w, f in weighted]
    zero = sum(w for w, cdf in parts if cdf is None)
    parts = [(w, cdf) for w, cdf in parts if cdf is not None]
    if not parts:
        return (math.nan, math.nan)
    values = [f.coef[term] for _, f in weighted if term in f.coef]
    top, low = max(values), min(values)

    def mixture(x):
        return zero + sum(w * float(cdf(x)) for w, cdf in parts)

    def quantile(q):
        if mixture(0.0) >= q:
            return 0.0
        a, b = math.log(low) - 1.0, math.log(top) + 1.0
        while mixture(math.exp(a)) > q:
            a -= 2.0 * (b - a)
        while mixture(math.exp(b)) < q:
            b += 2.0 * (b - a)
        return math.exp(halve(lambda x: mixture(math.exp(x)) < q, a, b, _BISECTIONS, 1e-9))
    lo = quantile(p)
    if selection is not None and selected is not None and term in selected.coef:
        lo = min(lo, selective_lower(selected.coef[term], *selection, level))
    return math.sqrt(lo), math.sqrt(quantile(1.0 - p))
