"""
Wavelet (PyWavelets) and median denoising of IMU rate samples, batch and block-streaming.

Wavelet method (thesis section 4.4.1, MATLAB ``wden`` style): a ``level``-level discrete
wavelet transform (default ``sym8``, the thesis's choice), each detail level thresholded, the
approximation kept, inverse transform.

* Noise level per level: the MAD of that level's detail coefficients / 0.6745 (level-dependent,
  MATLAB's ``'mln'``), or given: the per-sample white-noise standard deviation sigma (for
  example from the live white-noise coefficient N of the allan node: sigma = N sqrt(fs)); an
  orthonormal transform keeps white noise at sigma on every level.
* Threshold rules, lambda = sigma_j x t: ``universal`` t = sqrt(2 ln n) (VisuShrink,
  ``'sqtwolog'``), ``minimax`` t = 0.3936 + 0.1829 log2 n (0 for n <= 32, ``'minimaxi'``),
  ``sure`` t minimising Stein's unbiased risk on that level (``'rigrsure'``).  n is ``n_ref``,
  by default the number of samples being denoised.
* ``soft`` or ``hard`` thresholding.

Median method: a running median over ``median_window`` samples (the thesis used 20; the
default here is 21 so the window is centred).

Block streaming (:class:`BlockDenoiser`, docs/online.md "Blocks"): output comes ``hop`` samples
at a time, each from a block reaching ``margin`` samples before and after them, with block starts
on multiples of 2^level; with a data-independent threshold (sigma and ``n_ref`` given) the output
equals :func:`denoise` of the whole record for every sample (``test_denoise.py``), with MAD or
SURE each block is :func:`denoise` of that block.  Latency: at most ``margin + hop`` samples
(:func:`block_geometry`).
"""

import math

import numpy as np
import pywt
import scipy.ndimage

from .units import discrete_white_std

METHODS = ('wavelet', 'median')
RULES = ('universal', 'minimax', 'sure')
MODES = ('soft', 'hard')
_MAD_SCALE = 0.6744897501960817  # median |Z| of a standard normal
#: Decomposition levels of the streaming default: sym8 at level 4 waits 240 samples (2.4 s at
#: 100 Hz, 0.24 s at 1 kHz) instead of the 61,440 of the thesis's 12 levels.
LIVE_LEVEL = 4


def _as_2d(data):
    data = np.asarray(data, dtype=float)
    return (data[:, None], True) if data.ndim == 1 else (data, False)


def sure_threshold(x):
    """
    SURE threshold (in units of x, which must be normalised to unit noise std).

    Minimises Stein's unbiased risk estimate of soft thresholding over the candidates |x_i|.
    """
    x = np.abs(np.asarray(x, dtype=float))
    n = x.size
    if n == 0:
        return 0.0
    sq = np.sort(x * x)
    cum = np.cumsum(sq)
    k = np.arange(1, n + 1)
    risk = (n - 2.0 * k + cum + (n - k) * sq) / n
    return float(math.sqrt(sq[int(np.argmin(risk))]))


def rule_factor(rule, n_ref):
    """Threshold factor t (lambda = sigma t) of a data-independent rule for n_ref samples."""
    if rule == 'universal':
        return math.sqrt(2.0 * math.log(max(n_ref, 2)))
    if rule == 'minimax':
        return 0.3936 + 0.1829 * math.log2(n_ref) if n_ref > 32 else 0.0
    raise ValueError(f'rule {rule!r} depends on the data')


def _threshold(coeffs, lam, mode):
    if mode == 'soft':
        return np.sign(coeffs) * np.maximum(np.abs(coeffs) - lam, 0.0)
    return np.where(np.abs(coeffs) > lam, coeffs, 0.0)


def check_options(method='wavelet', wavelet='sym8', level=12, rule='universal', mode='soft',
                  median_window=21):
    """Validate denoising options; raise ValueError with the reason."""
    for name, value, allowed in (('method', method, METHODS), ('rule', rule, RULES),
                                 ('mode', mode, MODES)):
        if value not in allowed:
            raise ValueError(f'{name} must be one of {", ".join(allowed)}')
    if wavelet not in pywt.wavelist(kind='discrete'):
        raise ValueError(f'unknown discrete wavelet {wavelet!r} (e.g. haar, db4, sym8)')
    if int(level) < 1 or int(level) > 20:
        raise ValueError('level must be between 1 and 20')
    if int(median_window) < 1:
        raise ValueError('median_window must be >= 1')


def denoise(data, rate_hz=None, method='wavelet', wavelet='sym8', level=12, rule='universal',
            mode='soft', sigma=None, noise_density=None, n_ref=None, median_window=21):
    """
    Denoise rate samples (module docstring); returns an array shaped like ``data``.

    ``data``: (n,) or (n, A) rate samples, SI (rad/s, m/s^2); ``level`` is reduced to what the
    record length allows.  ``sigma``: the per-sample white-noise std per axis (SI), used on
    every level instead of the MAD estimate; or ``noise_density``: N per axis (rad/s/sqrt(Hz),
    m/s^2/sqrt(Hz)), sigma = N sqrt(``rate_hz``, Hz).  ``n_ref``: n of the universal / minimax
    threshold (default: the number of samples); ``median_window`` in samples.
    """
    check_options(method, wavelet, level, rule, mode, median_window)
    x, flat = _as_2d(data)
    n, n_axes = x.shape
    if n == 0:
        return np.asarray(data, dtype=float).copy()
    if method == 'median':
        out = scipy.ndimage.median_filter(x, size=(int(median_window), 1), mode='nearest')
        return out[:, 0] if flat else out
    if noise_density is not None:
        if not rate_hz:
            raise ValueError('noise_density needs rate_hz')
        sigma = discrete_white_std(np.asarray(noise_density, dtype=float), rate_hz)
    if sigma is not None:
        sigma = np.broadcast_to(np.asarray(sigma, dtype=float), (n_axes,))
    w = pywt.Wavelet(wavelet)
    levels = min(int(level), pywt.dwt_max_level(n, w.dec_len))
    if levels < 1:
        return (x[:, 0] if flat else x).copy()
    coeffs = pywt.wavedec(x, w, mode='symmetric', level=levels, axis=0)
    n_ref = n if n_ref is None else int(n_ref)
    for j in range(1, len(coeffs)):
        d = coeffs[j]
        sig = np.median(np.abs(d), axis=0) / _MAD_SCALE if sigma is None else sigma
        if rule == 'sure':
            lam = np.array([s * sure_threshold(d[:, a] / s) if s > 0 else 0.0
                            for a, s in enumerate(sig)])
        else:
            lam = sig * rule_factor(rule, n_ref)
        coeffs[j] = _threshold(d, lam[None, :], mode)
    out = pywt.waverec(coeffs, w, mode='symmetric', axis=0)[:n]
    return out[:, 0] if flat else out


def block_geometry(method='wavelet', wavelet='sym8', level=12, median_window=21, rate_hz=100.0,
                   hop_s=0.1):
    """
    Block layout of :class:`BlockDenoiser`: ``(margin, hop, align)`` in samples.

    ``margin`` is the context needed on each side of an output sample for it to equal the
    whole-record transform: (filter length - 1) x 2^level for the wavelet method (the support
    of a level-``level`` coefficient), window // 2 for the median; ``hop`` is the output step
    (a multiple of ``align`` = 2^level, about ``hop_s``).  Latency: ``margin`` to
    ``margin + hop`` samples.
    """
    if method == 'median':
        align = 1
        margin = int(median_window) // 2 + 1
    else:
        align = 2 ** int(level)
        margin = (pywt.Wavelet(wavelet).dec_len - 1) * align
    hop = align * max(1, int(math.ceil(hop_s * rate_hz / align)))
    return margin, hop, align


class BlockDenoiser:
    """
    Streaming denoiser on overlapping blocks with bounded latency (see module docstring).

    ``rate_hz`` in Hz, ``n_axes`` columns, ``hop_s`` the output step in s (rounded up to a
    multiple of 2^level samples); ``options``: those of :func:`denoise`.  Without ``n_ref`` the
    threshold uses the block length; the default level is :data:`LIVE_LEVEL`, not 12.
    """

    def __init__(self, rate_hz, n_axes=6, hop_s=0.1, **options):
        self.rate_hz = float(rate_hz)
        self.n_axes = int(n_axes)
        self.options = dict(options)
        self.options.setdefault('level', LIVE_LEVEL)
        check_options(**{k: v for k, v in self.options.items()
                         if k in ('method', 'wavelet', 'level', 'rule', 'mode', 'median_window')})
        geometry = {k: self.options[k] for k in ('method', 'wavelet', 'level', 'median_window')
                    if k in self.options}
        self.margin, self.hop, self.align = block_geometry(rate_hz=rate_hz, hop_s=hop_s,
                                                           **geometry)
        self.block_len = 2 * self.margin + self.hop
        self.options.setdefault('n_ref', self.block_len)
        self.options['rate_hz'] = self.rate_hz
        # Ring of the newest samples: left margin + hop + right margin.
        self._buf = np.zeros((self.block_len, self.n_axes))
        self._start = 0      # stream index of _buf[0]
        self._count = 0      # samples received
        self._emitted = 0    # samples output

    @property
    def latency_samples(self):
        """Worst-case delay between a sample's arrival and its output, samples."""
        return self.margin + self.hop - 1

    @property
    def latency_s(self):
        """Worst-case latency, s."""
        return self.latency_samples / self.rate_hz

    def memory_bytes(self):
        """Bytes held (fixed)."""
        return self._buf.nbytes

    def set_noise(self, sigma=None, noise_density=None):
        """Use a given white-noise level from now on (None for both: back to MAD)."""
        self.options['sigma'] = sigma
        self.options['noise_density'] = noise_density

    def _emit(self, end):
        """Denoise and return the samples [emitted, emitted + hop), the block ending at end."""
        first = self._emitted
        lo = max(0, first - self.margin)
        block = self._buf[lo - self._start:end - self._start]
        out = denoise(block, **self.options)
        return out[first - lo:first - lo + min(self.hop, end - first)]

    def _drop_old(self):
        """Keep only the left margin of the next output (it starts on a multiple of 2^level)."""
        new_start = max(0, self._emitted - self.margin)
        shift = new_start - self._start
        if shift > 0:
            keep = self._count - new_start
            self._buf[:keep] = self._buf[shift:shift + keep]
            self._start = new_start

    def push(self, block):
        """Add samples (n, n_axes); return the denoised samples now ready (k, n_axes)."""
        block = np.asarray(block, dtype=float)
        if block.ndim == 1:
            block = block[:, None]
        outputs = []
        i, n = 0, block.shape[0]
        while i < n:
            # Fill up to the end of the block the next output needs.
            need_end = self._emitted + self.hop + self.margin
            take = min(n - i, need_end - self._count)
            pos = self._count - self._start
            self._buf[pos:pos + take] = block[i:i + take]
            self._count += take
            i += take
            if self._count == need_end:
                outputs.append(self._emit(need_end))
                self._emitted += self.hop
                self._drop_old()
        return np.concatenate(outputs) if outputs else np.zeros((0, self.n_axes))

    def flush(self):
        """Denoise and return every sample not yet output (end of the stream)."""
        outputs = []
        while self._emitted < self._count:
            out = self._emit(self._count)
            outputs.append(out)
            self._emitted += out.shape[0]
            self._drop_old()
        return np.concatenate(outputs) if outputs else np.zeros((0, self.n_axes))
