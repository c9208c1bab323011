"""
A noise model as an endless stream of device output, for simulated devices that run for hours.

:func:`~imu_allan.core.simulation.simulate.simulate` makes one record; a simulated device makes its
noise in blocks, and a record cut into independent blocks has the wrong Allan variance at averaging
times near and above the block length: flicker, random walk, Gauss-Markov and sinusoid would
restart at every block.  :class:`NoiseStream` carries every term over (``simulate_axis`` with a
state; bias instability from the bank of first-order sections,
:func:`~imu_allan.core.simulation.simulate.flicker_bank`) and the device's window over the internal
samples of the previous block, so any split of the stream into blocks gives one continuous record.
"""

import numpy as np

from .simulate import scaled_white, simulate_axis
from ..model import NoiseModel


class NoiseStream:
    """
    Successive blocks of a noise model's samples through a device processing.

    ``model``, ``seed`` and ``axes`` as :func:`.simulate.simulate`; ``processing`` (a
    :class:`.device_processing.DeviceProcessing`) may be replaced between blocks
    (:attr:`processing`), the internal rate staying the same; ``history`` internal samples are
    kept for the window: the longest window it may change to (default: the first one's).
    """

    def __init__(self, model, processing, seed=None, axes=None, history=None):
        """Start the stream: draw the internal samples the first window reaches back into."""
        self.model = NoiseModel.from_dict(model) if isinstance(model, dict) else model
        self.rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self.axes = list(axes) if axes is not None else self.model.axes
        self.history = int(history or processing.window)
        self._processing = processing
        self.processing = processing  # checked by the setter
        self._state = [{} for _ in self.axes]   # per axis: what each term carries over
        self._tail = self._internal(self.history - 1)

    @property
    def processing(self):
        """Return the processing of the next block."""
        return self._processing

    @processing.setter
    def processing(self, value):
        if value.internal_rate_hz != self._processing.internal_rate_hz:
            raise ValueError('the internal rate of a stream cannot change')
        if value.window > self.history:
            raise ValueError(f'window {value.window} exceeds the {self.history} internal '
                             f'samples the stream keeps')
        self._processing = value

    def _internal(self, n):
        """Draw the next ``n`` internal samples of every axis, ``(n, axes)``."""
        out = np.empty((n, len(self.axes)))
        for j, axis in enumerate(self.axes):
            terms = scaled_white(self.model.terms.get(axis, {}), self._processing)
            out[:, j] = simulate_axis(terms, n, self._processing.internal_rate_hz, self.rng,
                                      self._state[j])
        return out

    def take(self, n):
        """
        Return the next ``n`` output samples, ``(n, axes)`` float64, SI.

        After a change of :attr:`processing` the first window still holds internal samples
        drawn with the previous white-noise scale (window - 1 internal samples).
        """
        p = self._processing
        n = int(n)
        fresh = self._internal(n * p.decimation)
        internal = np.concatenate([self._tail, fresh])
        out = p.filter_decimate(internal[len(internal) - (p.window - 1 + len(fresh)):])
        self._tail = internal[len(internal) - (self.history - 1):]
        return p.rounded(out)
