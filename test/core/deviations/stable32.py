"""Read the Stable32 tables of test/core/data/stable32 (README there names their source)."""

from pathlib import Path

from imu_allan.core.allan.edf import CI_LEVEL
from imu_allan.core.allan.estimate import _phase
import numpy as np
from scipy import stats

DATA = Path(__file__).resolve().parents[1] / 'data' / 'stable32'
#: The confidence factor: the tables print 0.683; their bounds are those of erf(1/sqrt 2).
LEVEL = CI_LEVEL


def phase_dat():
    """PHASE.DAT as rate samples y = diff(x) (tau0 = 1 s), shape (1000, 1)."""
    x = np.loadtxt(DATA / 'PHASE.DAT', comments='#')
    return np.diff(x)[:, None]


def phase_dat_phase():
    """Return the package's phase of PHASE.DAT (A, N) in sample units."""
    return _phase(phase_dat())


def table(name, commented=False):
    """
    Rows of a table: dict of arrays m, tau, n, alpha, low, dev, high.

    ``commented``: also the data rows commented out upstream ('#' followed by seven numbers).
    """
    rows = []
    for line in (DATA / name).read_text().splitlines():
        text = line.strip()
        if text.startswith('#'):
            if not commented:
                continue
            text = text[1:]
        try:
            values = [float(v) for v in text.split()]
        except ValueError:
            continue
        if len(values) == 7:
            rows.append(values)
    rows = np.array(rows)
    return {'m': rows[:, 0].astype(int), 'tau': rows[:, 1], 'n': rows[:, 2].astype(int),
            'alpha': rows[:, 3].astype(int), 'low': rows[:, 4], 'dev': rows[:, 5],
            'high': rows[:, 6]}


def chi2_quantile(q, edf):
    """
    Stable32's chi-square quantile with lower tail ``q`` (its CICS3.c as read by A. Wallin).

    Up to 100 degrees of freedom an iteration to 1e-4 of the probability (the exact quantile to
    the tables' digits); above, Wilson-Hilferty (Abramowitz & Stegun 26.4.17) on the normal
    quantile of A&S 26.2.22 with Stable32's misprint 0.27601 for the coefficient 0.27061
    (A. Wallin, "Fun with chi-squared", 2020; allantoolkit ``ci.chi2_ppf_stable32``).
    """
    if edf <= 100:
        return stats.chi2.ppf(q, edf)
    t = np.sqrt(-2.0 * np.log(min(q, 1.0 - q)))
    z = t - (2.30753 + 0.27601 * t) / (1.0 + 0.99229 * t + 0.04481 * t * t)
    z = -z if q < 0.5 else z
    return edf * (1.0 - 2.0 / (9.0 * edf) + z * np.sqrt(2.0 / (9.0 * edf))) ** 3


def bounds(dev, edf, level=LEVEL):
    """Stable32's 'Min Sigma' and 'Max Sigma' of a deviation with ``edf`` degrees of freedom."""
    p = (1.0 - level) / 2.0
    low = [d * np.sqrt(e / chi2_quantile(1.0 - p, e)) for d, e in zip(dev, edf)]
    high = [d * np.sqrt(e / chi2_quantile(p, e)) for d, e in zip(dev, edf)]
    return np.array(low), np.array(high)
