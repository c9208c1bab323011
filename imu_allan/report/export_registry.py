"""
The exporter registry: :class:`Exporter` and :data:`EXPORTERS` (see :mod:`.exporters`).

Its own module so that the dependency points one way: :mod:`.exporters` (the estimators'
formats, the header, the API) and :mod:`.sim_exporters` (Gazebo, PX4) both import it, and
:mod:`.exporters` imports :mod:`.sim_exporters` to register the simulators' formats; nothing
here imports either.
"""

from dataclasses import dataclass
from typing import Callable

from ..core.overbound import WHITE_WALK


@dataclass(frozen=True)
class Exporter:
    """One consumer's file format (see the docstring of :mod:`.exporters`)."""

    name: str
    files: tuple
    consumer: str
    time_base: str            # 'continuous' or 'per sample'
    conversion: str           # how N and K become the written numbers (f = rate in Hz)
    build: Callable
    render: Callable
    per_axis: bool = False    # True: one number per axis; False: the worst axis per sensor
    #: the consumer's own noise model (terms of core/terms.py), what ``--overbound`` fits
    model: tuple = WHITE_WALK
    #: what one overbound of ``model`` covers: ``'axis'`` (each axis) or ``'sensor'`` (the
    #: envelope of a sensor's axes, for one set of values per sensor)
    overbound_over: str = 'axis'


EXPORTERS = {}


def register(exporter):
    """Add (or replace) an exporter in the registry."""
    EXPORTERS[exporter.name] = exporter
    return exporter
