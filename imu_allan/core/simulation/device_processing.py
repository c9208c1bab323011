"""
An IMU's own processing of its samples: a moving-average window, decimation, float32 output.

The LORD MicroStrain 3DM-GX3-25 (DCP-GX3 manual, command 0xDB; reference/gx3_protocol.md
section 7.3) forms a 1 kHz internal stream of gyro and accelerometer samples, averages the last
``window`` of them (1..32, default 15) and sends every ``decimation``-th average (output rate
1000 / decimation Hz) as an IEEE float32.  :class:`DeviceProcessing` is that chain and its exact
effect on white noise, so the simulator, the tests and the fit share one description.

White noise through it (window M taps at the internal rate f_i, decimation D, output rate
f_o = f_i / D): output j is the mean of internal samples jD - M + 1 .. jD, so two outputs k
apart share max(0, M - |k| D) internal samples and their correlation is

    rho_k = max(0, 1 - |k| D / M).

The window has unit gain at 0 Hz, but keeping every D-th average folds the aliases at
multiples of f_o onto 0 Hz: the output's low-frequency density is c times the internal one,

    c = (D / M) sum_k rho_k      (10/9 for M = 15, D = 10; 1 when D divides M; D / M if M <= D).

The package's noise models describe what is measured at the output, so the simulator gives the
internal white noise the density N / sqrt(c) (:attr:`DeviceProcessing.alias_gain`): the output's
Allan variance is then N^2 / tau at long tau, and at factor m (tau = m / f_o) exactly
N^2 / tau * r(m) (:meth:`DeviceProcessing.white_avar_ratio`), with r(1) = (1 - rho_1) /
sum_k rho_k (0.4 for M = 15, D = 10) and r(m) -> 1 as 1 - O(1/m).

Quantization (white phase noise of std Q at the internal rate, differenced) goes through the same
chain; unless D divides M the window's two ends do not cancel, and the output carries, besides
its 1/tau^2 part, white rate noise of density Q sqrt(2 f_i D) / M.
"""

from dataclasses import dataclass
import math
import numbers

import numpy as np

#: Frequencies per block in :meth:`DeviceProcessing.output_psd`.
_BLOCK = 1 << 15


@dataclass(frozen=True)
class DeviceProcessing:
    """
    Moving average of ``window`` internal samples, every ``decimation``-th kept, then rounded.

    ``internal_rate_hz``: the rate the window runs on, Hz (1000 on the 3DM-GX3-25); output
    rate = internal_rate_hz / decimation.  The values are rounded to ``output_dtype``
    (``'float32'``: what the device sends) and returned as float64, as a driver publishes
    them; None leaves them unrounded.
    """

    internal_rate_hz: float = 1000.0
    window: int = 15
    decimation: int = 10
    output_dtype: str = 'float32'

    def __post_init__(self):
        """Refuse values that describe no processing (ValueError with the reason)."""
        rate = self.internal_rate_hz
        if not (isinstance(rate, numbers.Real) and math.isfinite(rate) and rate > 0):
            raise ValueError(f'internal_rate_hz must be a positive number, got {rate!r}')
        for name in ('window', 'decimation'):
            value = getattr(self, name)
            if not isinstance(value, numbers.Integral) or isinstance(value, bool) or value < 1:
                raise ValueError(f'{name} must be an integer >= 1, got {value!r}')
        if self.output_dtype is not None:
            np.dtype(self.output_dtype)  # TypeError for a name numpy does not know

    @property
    def output_rate_hz(self):
        """Output rate, Hz."""
        return self.internal_rate_hz / self.decimation

    @property
    def window_s(self):
        """Length of the averaging window, s."""
        return self.window / self.internal_rate_hz

    def check_rate(self, rate_hz):
        """Raise ValueError unless ``rate_hz`` is this processing's output rate."""
        if not math.isclose(rate_hz, self.output_rate_hz, rel_tol=1e-9):
            raise ValueError(
                f'rate_hz {rate_hz:g} does not match the processing: internal rate '
                f'{self.internal_rate_hz:g} Hz / decimation {self.decimation} = '
                f'{self.output_rate_hz:g} Hz')

    def lag_correlation(self, k):
        """Correlation of outputs ``k`` apart (int or array) for white noise in: rho_k."""
        k = np.abs(np.asarray(k))
        return np.maximum(0.0, 1.0 - k * self.decimation / self.window)

    def _correlations(self):
        """rho_0, rho_1, ... up to the last non-zero one."""
        return self.lag_correlation(np.arange(math.ceil(self.window / self.decimation)))

    @property
    def alias_gain(self):
        """Output over internal white-noise density at low frequency: c (module docstring)."""
        rho = self._correlations()
        return self.decimation / self.window * (2.0 * rho.sum() - 1.0)

    def white_avar_ratio(self, m):
        """
        Allan variance of processed white noise over N^2 / tau at factor ``m`` (array): r(m).

        N is the output's low-frequency density (tau = m / output_rate_hz).  Exact: from the
        output autocovariance, AVAR(m) = (4 V(m) - V(2m)) / (2 m^2) with
        V(m) = sum_{|k| < m} (m - |k|) gamma_k, the variance of a sum of m outputs.
        """
        m = np.asarray(m, dtype=float)
        rho = self._correlations()
        lags = np.arange(rho.size)

        def v(n):
            # sum over |k| < n of (n - |k|) rho_k, the k = 0 term once
            w = np.maximum(0.0, n[..., None] - lags) * rho
            return 2.0 * w.sum(axis=-1) - n

        return (4.0 * v(m) - v(2.0 * m)) / (2.0 * m * (2.0 * rho.sum() - 1.0))

    def response(self, f):
        """
        Power response of the window at ``f`` (Hz, array): |H(f)|^2, 1 at 0 Hz.

        H(f) = sin(pi f M / f_i) / (M sin(pi f / f_i)), periodic in f_i (|H| = 1 at its
        multiples, the limit).
        """
        x = np.pi * np.asarray(f, dtype=float) / self.internal_rate_hz
        den = self.window * np.sin(x)
        # |sin x| below 1e-9: within 1e-9 of a multiple of pi, where |H| is 1 to 1e-16 M^2
        h = np.divide(np.sin(self.window * x), den, out=np.ones(x.shape),
                      where=np.abs(den) > 1e-9 * self.window)
        return h * h

    def output_psd(self, f, internal_psd):
        """
        Two-sided PSD of the output at ``f`` (Hz, 0 .. the output Nyquist frequency).

        ``internal_psd(nu)``: the two-sided PSD of the internal stream at ``nu`` (Hz, array in
        0 .. f_i / 2).  The output's is the sum, over the ``decimation`` internal frequencies
        that alias onto ``f``, of the window's response times the internal PSD.
        """
        f = np.asarray(f, dtype=float)
        flat = f.ravel()
        total = np.empty(flat.shape)
        # In blocks that stay in cache: fresh arrays of millions of values cost more in page
        # faults than in arithmetic on this machine.
        for start in range(0, flat.size, _BLOCK):
            total[start:start + _BLOCK] = self._output_psd(flat[start:start + _BLOCK],
                                                           internal_psd)
        return total.reshape(f.shape)

    def _output_psd(self, f, internal_psd):
        fi, fo, taps = self.internal_rate_hz, self.output_rate_hz, self.window
        # The aliases are f + k fo; their responses from the sines of f alone (angle addition:
        # numpy's sine costs 30-120 ns a value here, and the FFT flicker asks for millions).
        a = np.pi * f / fi
        sin_a, cos_a, sin_ma, cos_ma = np.sin(a), np.cos(a), np.sin(taps * a), np.cos(taps * a)
        total = np.zeros(f.shape)
        for k in range(self.decimation):
            b = np.pi * k / self.decimation
            num = sin_ma * math.cos(taps * b) + cos_ma * math.sin(taps * b)
            den = taps * (sin_a * math.cos(b) + cos_a * math.sin(b))
            # |H| is 1 where the denominator vanishes (the alias is a multiple of fi)
            gain = np.divide(num, den, out=np.ones(f.shape), where=np.abs(den) > 1e-9 * taps)
            nu = np.abs((f + k * fo + fi / 2.0) % fi - fi / 2.0)
            total += gain * gain * internal_psd(nu)
        return total

    def filter_decimate(self, internal):
        """
        Window and decimate: internal ``(window - 1 + n * decimation, ...)`` -> ``(n, ...)``.

        The first ``window - 1`` rows are the history the first window reaches back into; the
        rows after them come in groups of ``decimation``, and output j is the mean of the
        ``window`` rows that end with the last row of group j.  Not rounded.
        """
        x = np.asarray(internal, dtype=float)
        extra = len(x) - (self.window - 1)
        if extra < 0 or extra % self.decimation:
            raise ValueError(f'{len(x)} internal samples: need window - 1 + n * decimation '
                             f'(window {self.window}, decimation {self.decimation})')
        if extra == 0:
            return np.zeros((0,) + x.shape[1:])
        windows = np.lib.stride_tricks.sliding_window_view(x, self.window, axis=0)
        return windows[self.decimation - 1::self.decimation].mean(axis=-1)

    def rounded(self, values):
        """Values rounded to :attr:`output_dtype` (float64 array; unchanged if None)."""
        values = np.asarray(values, dtype=float)
        if self.output_dtype is None:
            return values
        return values.astype(self.output_dtype).astype(float)
