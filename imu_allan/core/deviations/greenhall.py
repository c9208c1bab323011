"""Greenhall & Riley's EDF: :func:`imu_allan.core.allan.edf.edf_greenhall` (one implementation)."""

from ..allan.edf import edf_greenhall  # noqa: F401 - the name core/fit/hadamard_check.py imports
