"""The in-memory form of an IMU recording that every reader returns."""

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ..core.units import AXES


class Temperatures(NamedTuple):
    """The ``sensor_msgs/Temperature`` readings of a bag, beside its Imu samples."""

    topic: str
    #: header stamps, s, on the clock of the Imu stamps, sorted
    t: np.ndarray
    #: deg C, one per stamp
    celsius: np.ndarray


@dataclass
class Samples:
    """
    Time-stamped IMU samples in SI units.

    Attributes
    ----------
    t : numpy.ndarray
        Shape (n,), time in seconds (header stamp for bags, device timer for raw captures).
    data : numpy.ndarray
        Shape (n, A), rad/s for gyro axes and m/s^2 for accel axes, columns in ``axes`` order.
    axes : tuple of str
        Axis names, a subset of :data:`imu_allan.core.units.AXES` in that order.
    source : str
        Where the samples came from (file name, topic).
    gravity : float
        m/s^2 per g used to convert the input, if it was in g.
    warnings : list of str
        Things the reader skipped or repaired, each one line.
    extra : dict
        Extra columns (for example ``mag_x``) by name, each shape (n,).
    integrity : str
        What the reader could and could not verify about the container (checksums), one line.
    topic : str
        Bags: the Imu topic read ('' for other inputs).
    frame_id : str
        Bags: the ``header.frame_id`` of the first message ('' for other inputs).
    temperature : Temperatures or None
        Bags with a ``sensor_msgs/Temperature`` topic, read with the Imu when asked
        (``read_samples(..., temperature=True)``, as ``analyze`` does): the topic and its
        readings; None otherwise.
    topic_types : dict or None
        Bags read by the direct MCAP and sqlite3 readers: ``{topic: message type}`` of every
        topic in the bag; None where the reader did not list them.

    """

    t: np.ndarray
    data: np.ndarray
    axes: tuple = AXES
    source: str = ''
    gravity: float = 9.80665
    warnings: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    integrity: str = ''
    topic: str = ''
    frame_id: str = ''
    temperature: 'Temperatures' = None
    topic_types: dict = None

    @property
    def n(self):
        """Return the number of samples."""
        return int(self.t.shape[0])
