"""
An IMU axis from textbook parts, streamed: the live calibration's generator.

Written for the live calibration (live_calibration.py) without the package's simulator
(``imu_allan.core.simulation``) or the calibration harness's generators (calibration_cases.py,
which shape the FFT of white noise): it imports nothing from ``imu_allan``, and every term is
made by another method, as a device would make it, block by block with its state carried
across calls, so a 24-hour record can be fed to the online pipeline as it is made.

Terms (continuous-time IEEE Std 952 coefficients, SI; ``truth`` keys as the package's):

* ``white_noise`` N: white rate noise, per-sample std N sqrt(f) at the rate it is made;
* ``quantization`` Q: white angle noise of std Q, differenced and divided by the interval
  (AVAR 3 Q^2 / tau^2);
* ``bias_instability`` B: flicker as a bank of first-order relaxation processes (Keshner,
  "1/f noise", Proc. IEEE 70, 1982): AR(1) processes with corner frequencies f_k spaced by
  a factor rho, each of stationary variance B^2 ln(rho) / pi.  Their Lorentzian spectra
  2 s^2 tau_k / (1 + (2 pi f tau_k)^2) sum to the two-sided PSD B^2 / (2 pi f) between the
  lowest and highest corners (the integral of ln-spaced Lorentzians of equal variance:
  s^2 = B^2 d(ln f_k) / pi), with a ripple under 0.1 % at three poles per decade.  The
  lowest corner lies a hundred times below 1 / T, the highest at the Nyquist frequency;
  each process starts from its stationary distribution;
* ``rate_random_walk`` K: cumulative sum of white steps of std K sqrt(tau0);
* ``rate_ramp`` R: R t;
* ``gauss_markov`` (sigma, tau_c): one AR(1) process of stationary std sigma.

A device (``Device``) makes the white noise and a line at an internal rate, averages
``taps`` consecutive internal samples, keeps every ``decimation``-th average and rounds the
output (white noise and slow terms) to an LSB, as MEMS IMUs do (the 3DM-GX3-25's window and
decimation, the ADIS16405's LSB).  The white-noise truth of such an output is what
:meth:`Device.white_density` computes in closed form: the averaged noise folded by the
decimation plus the rounding's q^2 / 12 per sample (Sheppard; the LSB is kept below 1.4
noise sigmas, where Widrow's theorem puts the rounding error's departure from uniform and
independent below 1e-4).
"""

from dataclasses import dataclass
import math

import numpy as np
from scipy.signal import lfilter

#: Flicker bank: poles per decade and the lowest corner as a fraction of 1 / T.
POLES_PER_DECADE = 3
LOWEST_CORNER = 0.01


@dataclass
class Device:
    """An IMU's processing: internal rate multiple, moving average, LSB, a line."""

    #: internal samples per output sample (the decimation) and averaged taps
    decimation: int = 1
    taps: int = 1
    #: output LSB in output noise sigmas (0: no rounding)
    lsb_sigmas: float = 0.0
    #: a line at the internal rate: (frequency_hz, amplitude in output noise sigmas) or None
    line: tuple = None

    def fold(self):
        """Low-frequency density^2 of the averaged, decimated white noise over N^2 (exact)."""
        m, d = self.taps, self.decimation
        return d * (m + 2.0 * sum(max(0, m - k * d) for k in range(1, m // d + 1))) / (m * m)

    def output_sigma(self, n_density, rate_hz):
        """Per-sample std of the averaged white noise at the output (before rounding)."""
        return n_density * math.sqrt(rate_hz * self.decimation / self.taps)

    def lsb(self, n_density, rate_hz):
        """Return the LSB (SI) for a white-noise density (continuous-time) at ``rate_hz``."""
        return self.lsb_sigmas * self.output_sigma(n_density, rate_hz)

    def white_density(self, n_density, rate_hz):
        """Continuous-time white density of the output: fold and rounding (module doc)."""
        q = self.lsb(n_density, rate_hz)
        return math.sqrt(n_density ** 2 * self.fold() + q * q / 12.0 / rate_hz)

    def correlated_lags(self):
        """Lags (output samples) over which the averaging correlates the white noise."""
        return max(self.taps - 1, 0) // self.decimation


class _AR1:
    """AR(1) processes x_k = phi x_{k-1} + e_k of stationary std ``sigma``, state carried."""

    def __init__(self, rng, sigma, phi):
        self.rng = rng
        self.phi = np.atleast_1d(np.asarray(phi, dtype=float))
        self.sd = np.atleast_1d(np.asarray(sigma, dtype=float)) * np.sqrt(1.0 - self.phi ** 2)
        self.state = np.atleast_1d(np.asarray(sigma, dtype=float)) * rng.standard_normal(
            self.phi.size)  # stationary start

    def take(self, n):
        out = np.zeros(n)
        for k in range(self.phi.size):
            e = self.sd[k] * self.rng.standard_normal(n)
            y, zi = lfilter([1.0], [1.0, -self.phi[k]], e, zi=[self.phi[k] * self.state[k]])
            self.state[k] = y[-1]
            out += y
        return out


class IndependentAxis:
    """
    One axis of an IMU, streamed: ``next(n)`` returns the next n output samples (SI).

    ``truth``: {term: value} (``gauss_markov``: (sigma, tau_c)); ``rate_hz``: output rate;
    ``duration_s``: the longest record it will make (places the flicker bank's lowest corner);
    ``device``: a :class:`Device` or None (white noise made at the output rate, no rounding).
    """

    def __init__(self, truth, rate_hz, duration_s, rng, device=None):
        self.truth = dict(truth)
        self.rate = float(rate_hz)
        self.rng = rng
        self.device = device or Device()
        self.t = 0  # output samples made
        dt = 1.0 / self.rate
        self.flicker = None
        b = self.truth.get('bias_instability', 0.0)
        if b > 0:
            f_lo, f_hi = LOWEST_CORNER / duration_s, 0.5 * self.rate
            n_poles = int(math.ceil(math.log10(f_hi / f_lo) * POLES_PER_DECADE)) + 1
            corners = f_lo * (f_hi / f_lo) ** (np.arange(n_poles) / (n_poles - 1))
            rho = corners[1] / corners[0]
            phi = np.exp(-2.0 * math.pi * corners * dt)
            self.flicker = _AR1(rng, np.full(n_poles, b * math.sqrt(math.log(rho) / math.pi)), phi)
        self.markov = None
        if 'gauss_markov' in self.truth:
            sigma, tau_c = self.truth['gauss_markov']
            self.markov = _AR1(rng, sigma, math.exp(-dt / tau_c))
        self.walk = 0.0
        self.angle = self.truth.get('quantization', 0.0) * rng.standard_normal()
        self.line_phase = rng.uniform(0.0, 2.0 * math.pi)
        self.window = np.zeros(max(self.device.taps - 1, 0))  # the average's last inputs

    def _fast(self, n):
        """Return n output samples of the device's averaged, decimated white noise and line."""
        dev = self.device
        n_in = n * dev.decimation
        rate_in = self.rate * dev.decimation
        fast = self.truth.get('white_noise', 0.0) * math.sqrt(rate_in) * self.rng.standard_normal(
            n_in)
        if dev.line is not None:
            f, sigmas = dev.line
            w = 2.0 * math.pi * f / rate_in
            m = dev.taps
            gain = abs(math.sin(w * m / 2.0) / (m * math.sin(w / 2.0))) if m > 1 else 1.0
            amp = sigmas * dev.output_sigma(self.truth.get('white_noise', 0.0), self.rate)
            fast += amp / max(gain, 1e-3) * np.sin(self.line_phase + w * np.arange(n_in))
            self.line_phase = (self.line_phase + w * n_in) % (2.0 * math.pi)
        if dev.taps == 1:
            return fast[dev.decimation - 1::dev.decimation]
        x = np.concatenate((self.window, fast))
        self.window = x[-(dev.taps - 1):]
        c = np.concatenate(([0.0], np.cumsum(x)))
        means = (c[dev.taps:] - c[:-dev.taps]) / dev.taps  # mean of taps ending at each input
        return means[dev.decimation - 1::dev.decimation]

    def take(self, n):
        """Return the next ``n`` output samples."""
        dt = 1.0 / self.rate
        y = self._fast(n)
        q = self.truth.get('quantization', 0.0)
        if q > 0:
            angles = np.concatenate(([self.angle], q * self.rng.standard_normal(n)))
            self.angle = angles[-1]
            y += np.diff(angles) / dt
        if self.flicker is not None:
            y += self.flicker.take(n)
        if self.markov is not None:
            y += self.markov.take(n)
        k = self.truth.get('rate_random_walk', 0.0)
        if k > 0:
            walk = self.walk + np.cumsum(k * math.sqrt(dt) * self.rng.standard_normal(n))
            self.walk = walk[-1]
            y += walk
        r = self.truth.get('rate_ramp', 0.0)
        if r > 0:
            y += r * dt * (self.t + np.arange(n))
        self.t += n
        lsb = self.device.lsb(self.truth.get('white_noise', 0.0), self.rate)
        return np.round(y / lsb) * lsb if lsb > 0 else y

    def white_truth(self):
        """Return the white-noise density the output carries (continuous-time; :class:`Device`)."""
        return self.device.white_density(self.truth.get('white_noise', 0.0), self.rate)

    def line_alias_hz(self):
        """Frequency the line appears at in the output (Hz), or None."""
        if self.device.line is None:
            return None
        f = self.device.line[0]
        return abs(f - self.rate * round(f / self.rate))
