"""
NBS14 1000-point frequency set against NIST SP1065 table III (Stable32-checked values).

Generator (SP1065 p. 107; peers_and_estimators.md 4): n_0 = 1234567890,
n_{i+1} = 16807 n_i mod 2147483647, divided by 2147483647.  Table III lists every deviation
at tau = 1, 10, 100 (Theo1 at averaging factors 10, 100, 1000), to 7 digits (MTOTDEV and
Theo1 to 5, "no bias correction"); HTOTDEV there carries the white FM bias correction
(divided by sqrt(0.995) at m > 1, as Stable32 prints it).  Tolerance rtol 1e-4 as allantools.
"""

from imu_allan.core.allan.estimate import _phase
from imu_allan.core.deviations import api
import numpy as np
import pytest

TABLE_III = {
    'adev': [2.922319e-1, 9.965736e-2, 3.897804e-2],
    'oadev': [2.922319e-1, 9.159953e-2, 3.241343e-2],
    'mdev': [2.922319e-1, 6.172376e-2, 2.170921e-2],
    'totdev': [2.922319e-1, 9.134743e-2, 3.406530e-2],
    'hdev': [2.943883e-1, 1.052754e-1, 3.910860e-2],
    'ohdev': [2.943883e-1, 9.581083e-2, 3.237638e-2],
    'tdev': [1.687202e-1, 3.563623e-1, 1.253382],
    'htotdev': [2.943883e-1, 9.614787e-2, 3.058103e-2],
    'mtotdev': [2.0664e-1, 5.5529e-2, 1.9547e-2],
    'theo1': [1.0757e-1, 3.1789e-2, 5.0524e-3],
}


def nbs14_1000():
    n = [1234567890]
    for _ in range(999):
        n.append(16807 * n[-1] % 2147483647)
    assert n[1] == 395529916
    return np.array(n, dtype=float)[:, None] / 2147483647.0


@pytest.mark.parametrize('kind', sorted(TABLE_III))
def test_table_iii(kind):
    x = _phase(nbs14_1000())
    ms = np.array([10, 100, 1000] if kind == 'theo1' else [1, 10, 100])
    dev = np.sqrt(api.raw_variance(kind, x, ms)[:, 0])
    if kind == 'tdev':
        dev = dev * ms / np.sqrt(3.0)
    if kind == 'htotdev':  # white FM (alpha 0) bias, SP1065's table value is corrected
        dev = dev / np.sqrt([api.bias_factor(kind, 0, m, 1001) for m in ms])
    np.testing.assert_allclose(dev, TABLE_III[kind], rtol=1e-4)
