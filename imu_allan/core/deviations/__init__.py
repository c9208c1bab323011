"""
The family of frequency-stability deviations (Stable32's): one module per family.

- :mod:`.allan_family`: adev, oadev, hdev, ohdev (NIST SP1065 eqs 7, 11, 18, 20)
- :mod:`.modified`: mdev, tdev (SP1065 eqs 14, 15)
- :mod:`.total`: totdev, mtotdev, htotdev (SP1065 eqs 25, 27, 29)
- :mod:`.theo`: theo1 (SP1065 eq 30); :mod:`.theobr`: its run-wide noise and bias (ThêoBR)
- :mod:`.kinds`: one entry per kind (what the dispatch reads); :mod:`.grid`: averaging factors;
  :mod:`.noise_id`: noise type per averaging time (the Greenhall & Riley EDF is
  :func:`imu_allan.core.allan.edf.edf_greenhall`);
  :mod:`.api`: :func:`deviation`.
"""

from .api import deviation, DeviationResult, extra_deviations, KINDS, parse_kinds

__all__ = ['DeviationResult', 'deviation', 'extra_deviations', 'KINDS', 'parse_kinds']
