"""
Does a fitted noise model describe the measured Allan variance?  The fit's adequacy test.

The log residuals r_i = ln(AVAR_i / model_i) - (psi(nu_i / 2) - ln(nu_i / 2)) (mean 0,
variance psi'(nu_i / 2)), adjusted by the best log-domain change of the fitted coefficients,
are projected on the first :data:`SMOOTH_MODES` Legendre polynomials of log tau over the
span: s = B' r and T = s' (B' Cov(r) B)^-1 s ~ chi^2(k) up to :data:`STATISTIC_SCALE`.  Why
smooth modes and not the GLS chi^2, and what it was measured to do: docs/method.md section 10.
Where it fails, the misfit is localised: runs of averaging times whose standardised log
residual exceeds :data:`RUN_Z`, kept when their worst point exceeds :data:`PEAK_Z`.
"""

from dataclasses import dataclass, field
import math

import numpy as np

from ..allan.log_chi2 import log_bias, log_sd
from ..scipy_compiled import function

_gammaincc = function('special', '_special_ufuncs', 'gammaincc')

#: p below this: the model does not describe the curve (a metrologist's 3.3-sigma).
ADEQUACY_LEVEL = 1e-3
#: Smooth modes (Legendre polynomials in log tau) the residuals are projected on.
SMOOTH_MODES = 8
#: The statistic's mean over its degrees of freedom on records the model describes, measured:
#: 0.93 on 360 records of the independent generator (five term sets; 1 h and 3 h at 100 Hz,
#: 1 h at 400 Hz), 0.87 on 192 realistic ones (filter, LSB, lines); T / 0.9 is compared with
#: chi^2 (docs/method.md, "Adequacy").  Below 1: the correlation model overstates the scatter
#: of smooth deviations a little, and the selection keeps the set that fits best.
STATISTIC_SCALE = 0.9
#: A misfit run: points beyond RUN_Z standard deviations, with one beyond PEAK_Z.
RUN_Z = 2.0
PEAK_Z = 3.5


def log_residuals(avar, model, edf, noise_share=1.0):
    """
    Return (r, sd): unbiased log residuals ln(avar / model) and their standard deviations.

    ``noise_share``: the part of the model AVAR that is noise (1 - a deterministic ramp's
    share, per tau): only that part scatters (chi-square with ``edf``), so the log's bias and
    spread scale with it (first order in the share).
    """
    r = np.log(avar / model) - noise_share * log_bias(edf)
    return r, noise_share * log_sd(edf)


@dataclass
class Misfit:
    """A span of averaging times the model does not describe."""

    tau_s: tuple          # (first, last) averaging time of the span, s
    ratio: float          # measured / model Allan deviation at the worst point
    effect: str = None    # what bends the curve there, when known

    def to_json(self):
        """JSON-ready dict (report.json ``axes.<axis>.fit.adequacy.misfit[]``)."""
        return {'tau_s': [float(self.tau_s[0]), float(self.tau_s[1])],
                'ratio': float(self.ratio), 'effect': self.effect}


@dataclass
class Adequacy:
    """The adequacy test of one axis's fit (see the module docstring)."""

    chi2: float
    dof: int
    p: float
    misfit: list = field(default_factory=list)

    @property
    def tested(self):
        """Return whether the test ran: enough averaging times for a finite p."""
        return bool(self.dof > 0 and math.isfinite(self.p))

    @property
    def adequate(self):
        """
        Return True when the test ran and did not reject the model at :data:`ADEQUACY_LEVEL`.

        An untested fit (fewer than 3 averaging times) is not adequate: "not tested", never
        "describes the data".
        """
        return self.tested and not self.p < ADEQUACY_LEVEL

    @property
    def rejected(self):
        """Return True when the test ran and rejected the model (neither adequate nor untested)."""
        return self.tested and self.p < ADEQUACY_LEVEL

    @property
    def scale(self):
        """
        Factor the intervals of an inadequate fit are widened by: sqrt(chi2 / dof), else 1.

        The Birge ratio: the scatter the model leaves is chi2 / dof times what the fit's
        covariance expects, and an honest interval carries it (what the particle-data tables do
        with inconsistent measurements).  It does not make a biased number right; the verdict
        and the misfit spans say that.
        """
        if not self.rejected:
            return 1.0
        return math.sqrt(max(self.chi2 / (self.dof * STATISTIC_SCALE), 1.0))

    def to_json(self):
        """JSON-ready dict (report.json ``axes.<axis>.fit.adequacy``)."""
        return {'chi2': _finite(self.chi2), 'dof': int(self.dof), 'p': _finite(self.p),
                'tested': self.tested, 'adequate': self.adequate if self.tested else None,
                'interval_scale': float(self.scale),
                'misfit': [m.to_json() for m in self.misfit]}


def _finite(value):
    """Return a float for JSON, None where it is not finite (strict JSON has no NaN)."""
    return float(value) if math.isfinite(value) else None


def smooth_basis(tau, modes=SMOOTH_MODES):
    """Legendre polynomials P_0 .. P_{k-1} of log tau mapped onto [-1, 1], one column each."""
    x = np.log(np.asarray(tau, dtype=float))
    span = x[-1] - x[0]
    u = 2.0 * (x - x[0]) / span - 1.0 if span > 0 else np.zeros_like(x)
    return np.polynomial.legendre.legvander(u, modes - 1)


def smooth_statistic(r, sd, corr, sensitivities, basis):
    """
    Return (T, dof, p) of the smooth-mode test for log residuals ``r`` (module docstring).

    ``sd``: their standard deviations; ``corr``: the correlation matrix of the estimates;
    ``sensitivities``: d ln(model) / d c_j, one column per fitted linear coefficient (none is
    fine); ``basis``: the smooth modes, one column each (:func:`smooth_basis`).
    """
    cov = sd[:, None] * corr * sd[None, :]
    g = sensitivities
    if g.shape[1]:
        # the residual after the best log-domain adjustment of the fitted coefficients: can
        # the model's shapes describe the curve, whatever weights the fit itself used
        w_inv_g = np.linalg.solve(cov, g)
        info_inv = np.linalg.pinv(g.T @ w_inv_g)
        r = r - g @ (info_inv @ (w_inv_g.T @ r))
        cov = cov - g @ info_inv @ g.T
    m = basis.T @ cov @ basis
    vals, vecs = np.linalg.eigh(0.5 * (m + m.T))
    keep = vals > 1e-9 * max(float(vals.max()), 1e-300)
    s = vecs[:, keep].T @ (basis.T @ r)
    t = float(np.sum(s * s / vals[keep]))
    dof = int(keep.sum())
    return t, dof, (float(_gammaincc(0.5 * dof, 0.5 * t / STATISTIC_SCALE)) if dof else 1.0)


def misfit_runs(tau, z):
    """
    Spans the model misses: ``[(first, last, worst), ...]`` indices, the worst span first.

    A span is a run of consecutive points with |z| > :data:`RUN_Z` (one sign) holding a point
    beyond :data:`PEAK_Z`.
    """
    runs = []
    start = None
    for i in range(z.size + 1):
        inside = i < z.size and abs(z[i]) > RUN_Z and (
            start is None or np.sign(z[i]) == np.sign(z[start]))
        if inside and start is None:
            start = i
        elif not inside and start is not None:
            worst = start + int(np.argmax(np.abs(z[start:i])))
            if abs(z[worst]) > PEAK_Z:
                runs.append((start, i - 1, worst))
            start = i if i < z.size and abs(z[i]) > RUN_Z else None
    return sorted(runs, key=lambda run: -abs(z[run[2]]))


def assess(tau, avar, edf, corr, model, columns, name_effect=None, deterministic=None,
           nuisance=None, extra_sd=None):
    """
    Adequacy of a fitted model curve to measured AVAR (one axis, the fitted averaging times).

    ``model``: the fitted AVAR at ``tau``; ``columns``: each fitted linear term's AVAR
    contribution at ``tau`` (one column each: the sensitivities are columns / model);
    ``corr``: the fit's correlation matrix of the estimates; ``name_effect(lo, hi, ratio)``
    names what bends the curve over a misfit span (s, s, ADEV ratio), or returns None;
    ``deterministic``: the part of ``model`` from a deterministic term (a rate ramp), which
    adds to the estimate without scattering it; ``nuisance``: further directions (AVAR per
    tau, one column each) the estimate may move along without the model being wrong (a
    ramp's cross term with the noise's drift), and ``extra_sd`` the scatter (log units, per
    tau) that cross term adds beyond them.
    """
    tau = np.asarray(tau, dtype=float)
    if tau.size < 3:
        return Adequacy(math.nan, 0, math.nan)
    share = 1.0 if deterministic is None else np.clip(1.0 - deterministic / model, 1e-3, 1.0)
    r, sd = log_residuals(avar, model, edf, share)
    if extra_sd is not None:
        sd = np.hypot(sd, extra_sd)
    g = np.asarray(columns, float).reshape(tau.size, -1)
    if nuisance is not None:
        g = np.column_stack([g, np.asarray(nuisance, float).reshape(tau.size, -1)])
    t, dof, p = smooth_statistic(r, sd, corr, g / model[:, None],
                                 smooth_basis(tau, min(SMOOTH_MODES, tau.size // 4 or 1)))
    out = Adequacy(t, dof, p)
    if not out.rejected:
        return out
    z = r / sd
    for first, last, worst in misfit_runs(tau, z):
        ratio = math.sqrt(avar[worst] / model[worst])
        lo, hi = float(tau[first]), float(tau[last])
        out.misfit.append(Misfit((lo, hi), ratio,
                                 name_effect(lo, hi, ratio) if name_effect else None))
    return out
