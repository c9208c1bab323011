"""Read the Stable32 tables of test/core/data/stable32 (README there names their source)."""

from pathlib import Path

from imu_allan.core.allan import _phase
import numpy as np

DATA = Path(__file__).resolve().parents[1] / 'data' / 'stable32'


def phase_dat():
    """PHASE.DAT as rate samples y = diff(x) (tau0 = 1 s), shape (1000, 1)."""
    x = np.loadtxt(DATA / 'PHASE.DAT', comments='#')
    return np.diff(x)[:, None]


def phase_dat_phase():
    """Return the package's phase of PHASE.DAT (A, N) in sample units."""
    return _phase(phase_dat())


def table(name):
    """Rows of a table: dict of arrays m, tau, n, alpha, low, dev, high."""
    rows = np.loadtxt(DATA / name, comments='#')
    return {'m': rows[:, 0].astype(int), 'tau': rows[:, 1], 'n': rows[:, 2].astype(int),
            'alpha': rows[:, 3].astype(int), 'low': rows[:, 4], 'dev': rows[:, 5],
            'high': rows[:, 6]}
