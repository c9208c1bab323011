"""
Compiled sums of the O(N)-per-tau kinds (numba): adev, hdev, ohdev, mdev/tdev, totdev.

No temporaries (numpy makes three to five full-length arrays per averaging time), jobs run on
the package's thread pool (:func:`imu_allan.core.jit.map_threads`).  adev and hdev (stride
m: N / m terms), ohdev and totdev (N terms per m) are summed block by block over the phase,
every averaging time per 32 KiB block, as the Allan kernel (:mod:`..allan.kernel`): each
phase point comes from memory once per axis.  mdev is Stable32's recursion, blocked the
same way, four factors per loop.  The numpy versions in
:mod:`.allan_family`, :mod:`.modified` and :mod:`.total` are the oracles these are tested
against.
"""

import numpy as np

from .noise_id_kernel import gather_block
from ..jit import jit, map_threads

#: Fused multiply-adds only (no reassociation): the recursion's adds stay in order, and a
#: multiply and the add after it become one instruction with one rounding.  30 % less CPU
#: (0.41 -> 0.28 s on 1.7 M x 6: the two FP adders were the limit).  The sums differ from
#: numpy's unfused ones by rounding: 1e-14 on white noise, up to 2e-10 at m = 1 on random-walk
#: FM (phase ~ n^1.5), where both are 1e-11 to 6e-10 off the exact sums (test_compiled_paths).
_CONTRACT = {'contract'}


@jit(nogil=True, fastmath=_CONTRACT, inline='never')
def _modified_four(xa, ma, mb, mc, md, j0, j1, v, s, t):  # pragma: no cover - compiled
    # Stable32's recursion for four factors over steps j in [j0, j1): v[t + k] += x_{j+3m} -
    # 3 x_{j+2m} + 3 x_{j+m} - x_j, s[t + k] += v^2.  Four independent add chains per loop
    # (one chain left the core's other adders idle) and x_j loaded once for the four; each
    # chain in the one-factor order of operations (_modified_one's).
    x0 = xa[j0:]
    a1, a2, a3 = xa[j0 + ma:], xa[j0 + 2 * ma:], xa[j0 + 3 * ma:]
    b1, b2, b3 = xa[j0 + mb:], xa[j0 + 2 * mb:], xa[j0 + 3 * mb:]
    c1, c2, c3 = xa[j0 + mc:], xa[j0 + 2 * mc:], xa[j0 + 3 * mc:]
    d1, d2, d3 = xa[j0 + md:], xa[j0 + 2 * md:], xa[j0 + 3 * md:]
    va, vb, vc, vd = v[t], v[t + 1], v[t + 2], v[t + 3]
    sa, sb, sc, sd = s[t], s[t + 1], s[t + 2], s[t + 3]
    for j in range(j1 - j0):
        x = x0[j]
        va += a3[j] - 3.0 * a2[j] + 3.0 * a1[j] - x
        vb += b3[j] - 3.0 * b2[j] + 3.0 * b1[j] - x
        vc += c3[j] - 3.0 * c2[j] + 3.0 * c1[j] - x
        vd += d3[j] - 3.0 * d2[j] + 3.0 * d1[j] - x
        sa += va * va
        sb += vb * vb
        sc += vc * vc
        sd += vd * vd
    v[t], v[t + 1], v[t + 2], v[t + 3] = va, vb, vc, vd
    s[t], s[t + 1], s[t + 2], s[t + 3] = sa, sb, sc, sd


@jit(nogil=True, fastmath=_CONTRACT, inline='never')
def _modified_one(xa, m, j0, j1, v, s, t):  # pragma: no cover - compiled; tested vs numpy
    # One factor's recursion over steps [j0, j1), as _modified_four's chains.
    x0, x1, x2, x3 = xa[j0:], xa[j0 + m:], xa[j0 + 2 * m:], xa[j0 + 3 * m:]
    vt, st = v[t], s[t]
    for j in range(j1 - j0):
        vt += x3[j] - 3.0 * x2[j] + 3.0 * x1[j] - x0[j]
        st += vt * vt
    v[t], s[t] = vt, st


@jit(nogil=True, fastmath=False)
def _modified_blocks(xa, ms, s):  # pragma: no cover - compiled; tested vs numpy
    # s[t] = sum over j = 0 .. N - 3m of v_j^2, v_j the m-sum of second differences at ms[t]
    # (ascending): the first one summed directly, the others by Stable32's recursion,
    # v_{j+1} = v_j + x_{j+3m} - 3 x_{j+2m} + 3 x_{j+m} - x_j.  Block by block over j, every
    # factor per block, four at a time: one pass per factor streamed the phase's four
    # neighbourhoods x_j .. x_{j+3m} from memory once per m; here each block's are read for
    # every factor while they sit in the caches.
    n = xa.shape[0]
    n_tau = ms.shape[0]
    v = np.zeros(n_tau)
    last = np.empty(n_tau, dtype=np.int64)  # steps j < last[t]: count - 1 of them
    for t in range(n_tau):
        m = ms[t]
        for i in range(m):
            v[t] += xa[i + 2 * m] - 2.0 * xa[i + m] + xa[i]
        s[t] = v[t] * v[t]
        last[t] = n - 3 * m
    for b0 in range(0, last[0], BLOCK):
        b1 = min(b0 + BLOCK, last[0])
        t = 0
        while t < n_tau and last[t] > b0:
            if t + 4 <= n_tau and last[t + 3] > b0:
                common = min(b1, last[t + 3])  # the fourth factor is the longest: fewest steps
                _modified_four(xa, ms[t], ms[t + 1], ms[t + 2], ms[t + 3], b0, common, v, s, t)
                for k in range(4):
                    end = min(b1, last[t + k])
                    if common < end:
                        _modified_one(xa, ms[t + k], common, end, v, s, t + k)
                t += 4
            else:
                _modified_one(xa, ms[t], b0, min(b1, last[t]), v, s, t)
                t += 1


#: Phase points per block of the overlapping sums (as :data:`..allan.kernel.BLOCK`: 32 KiB).
BLOCK = 4096


@jit(fastmath=True, nogil=True, inline='never')
def _third_one(xa, m, k0, k1):  # pragma: no cover - compiled; tested vs numpy
    # Views indexed from 0 in a function of their own: the form LLVM vectorises.
    x3, x2, x1, x0 = xa[k0 + 3 * m:], xa[k0 + 2 * m:], xa[k0 + m:], xa[k0:]
    s = 0.0
    for k in range(k1 - k0):
        d = x3[k] - 3.0 * x2[k] + 3.0 * x1[k] - x0[k]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _centred_one(xa, m, i0, i1):  # pragma: no cover - compiled; tested vs numpy
    lo, mid, hi = xa[i0 - m:], xa[i0:], xa[i0 + m:]
    s = 0.0
    for i in range(i1 - i0):
        d = lo[i] - 2.0 * mid[i] + hi[i]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _stride_one(xa, m, d, q0, q1):  # pragma: no cover - compiled; tested vs numpy
    # Squared d-th differences (2: Allan, 3: Hadamard) ending at q = q0, q0 + m, ... < q1,
    # in allan_family's order of operations (x_{k+2m} - 2 x_{k+m} + x_k, and the third).
    # Consecutive terms share all but one point: the d older ones are carried in registers,
    # one load per term instead of d + 1 (each a new cache line from m = 8 on); m = 1 runs
    # contiguous, the form LLVM vectorises.  2.8x (Allan) and 3.1x (Hadamard) less CPU here.
    s = 0.0
    if m == 1:
        x3, x2, x1 = xa[q0:], xa[q0 - 1:], xa[q0 - 2:]
        if d == 2:
            for k in range(q1 - q0):
                e = x3[k] - 2.0 * x2[k] + x1[k]
                s += e * e
        else:
            x0 = xa[q0 - 3:]
            for k in range(q1 - q0):
                e = x3[k] - 3.0 * x2[k] + 3.0 * x1[k] - x0[k]
                s += e * e
        return s
    if d == 2:
        a, b = xa[q0 - 2 * m], xa[q0 - m]
        for q in range(q0, q1, m):
            c = xa[q]
            e = c - 2.0 * b + a
            s += e * e
            a, b = b, c
    else:
        a, b, c = xa[q0 - 3 * m], xa[q0 - 2 * m], xa[q0 - m]
        for q in range(q0, q1, m):
            z = xa[q]
            e = z - 3.0 * c + 3.0 * b - a
            s += e * e
            a, b, c = b, c, z
    return s


@jit(nogil=True)
def _stride_blocks(xa, ms, d, acc, ks, offs, points):  # pragma: no cover - compiled
    # acc[t] += the squared non-overlapping d-th differences at stride ms[t] (adev, hdev):
    # block by block over the phase, every averaging time per block, each difference taken
    # where its last point x_q (q a multiple of m, q >= d m) lies.  One pass per m streamed
    # the whole phase from memory once per m below the cache line (8 points) and touched a
    # new line per term above it; here the block is in L1 and the d m points behind each term
    # in L2 (m up to a block) or few (m beyond it: one term per block at most).  The same
    # pass gathers the noise identification's points x_{jm}, j <= ks[t], into
    # points[offs[t] + j] (noise_id_kernel.layout; ks[t] = 0: none), the lines it just read.
    n = xa.shape[0]
    for b0 in range(0, n, BLOCK):
        b1 = min(b0 + BLOCK, n)
        for t in range(ms.shape[0]):
            m = ms[t]
            j = (b0 + m - 1) // m
            q0 = max(d * m, j * m)
            if q0 < b1:
                acc[t] += _stride_one(xa, m, d, q0, b1)
            if ks[t] > 0:
                gather_block(xa, m, ks[t], b0, b1, points, offs[t])


@jit(fastmath=True, nogil=True, inline='never')
def _third_four(xa, ma, mb, mc, md, k0, k1):  # pragma: no cover - compiled
    # _third_one of four factors in one loop, x_k loaded once for the four (as _centred_four).
    x0 = xa[k0:]
    a1, a2, a3 = xa[k0 + ma:], xa[k0 + 2 * ma:], xa[k0 + 3 * ma:]
    b1, b2, b3 = xa[k0 + mb:], xa[k0 + 2 * mb:], xa[k0 + 3 * mb:]
    c1, c2, c3 = xa[k0 + mc:], xa[k0 + 2 * mc:], xa[k0 + 3 * mc:]
    d1, d2, d3 = xa[k0 + md:], xa[k0 + 2 * md:], xa[k0 + 3 * md:]
    sa = sb = sc = sd = 0.0
    for k in range(k1 - k0):
        x = x0[k]
        ea = a3[k] - 3.0 * a2[k] + 3.0 * a1[k] - x
        eb = b3[k] - 3.0 * b2[k] + 3.0 * b1[k] - x
        ec = c3[k] - 3.0 * c2[k] + 3.0 * c1[k] - x
        ed = d3[k] - 3.0 * d2[k] + 3.0 * d1[k] - x
        sa += ea * ea
        sb += eb * eb
        sc += ec * ec
        sd += ed * ed
    return sa, sb, sc, sd


@jit(nogil=True)
def _hadamard_blocks(xa, ms, k_lo, k_hi, acc):  # pragma: no cover - compiled
    # acc[t] += sum of squared third differences at ms[t] (ascending) for k in [k_lo, k_hi),
    # k + 3m < N: block by block, every averaging time per block, so that each phase point
    # comes from memory once and the 3 m window behind it from the caches (as the Allan
    # kernel); four factors per loop over their common range (22 % less CPU than one).
    n_phase = xa.shape[0]
    n_tau = ms.shape[0]
    for k0 in range(k_lo, k_hi, BLOCK):
        k1 = min(k0 + BLOCK, k_hi)
        t = 0
        while t < n_tau:
            top = min(t + 4, n_tau)
            common = k0  # the group's common range [k0, common): the last factor is longest
            if top - t == 4:
                common = max(k0, min(k1, n_phase - 3 * ms[t + 3]))
                if common > k0:
                    sa, sb, sc, sd = _third_four(xa, ms[t], ms[t + 1], ms[t + 2], ms[t + 3],
                                                 k0, common)
                    acc[t] += sa
                    acc[t + 1] += sb
                    acc[t + 2] += sc
                    acc[t + 3] += sd
            for u in range(t, top):
                end = min(k1, n_phase - 3 * ms[u])
                if end > common:
                    acc[u] += _third_one(xa, ms[u], common, end)
            t = top


@jit(fastmath=True, nogil=True, inline='never')
def _centred_four(xa, ma, mb, mc, md, i0, i1):  # pragma: no cover - compiled
    # Four factors in one loop, as allan.kernel._sum_four: x_c loaded once for the four.
    mid = xa[i0:]
    la, ha = xa[i0 - ma:], xa[i0 + ma:]
    lb, hb = xa[i0 - mb:], xa[i0 + mb:]
    lc, hc = xa[i0 - mc:], xa[i0 + mc:]
    ld, hd = xa[i0 - md:], xa[i0 + md:]
    sa = sb = sc = sd = 0.0
    for i in range(i1 - i0):
        v = 2.0 * mid[i]
        da = la[i] - v + ha[i]
        db = lb[i] - v + hb[i]
        dc = lc[i] - v + hc[i]
        dd = ld[i] - v + hd[i]
        sa += da * da
        sb += db * db
        sc += dc * dc
        sd += dd * dd
    return sa, sb, sc, sd


@jit(fastmath=True, nogil=True, inline='never')
def _left_one(xa, ra, m, i0, i1):  # pragma: no cover - compiled; tested vs numpy
    # Centres c < m (c + m inside): x*_{c-m} = 2 x_0 - x_{m-c}, as total.reflect computes it,
    # x_{m-c} read ascending from the reversed phase ra (ra[j] = x_{N-1-j}): a descending
    # index kept numba's negative-index check and the loop scalar (3-4x the inside's cost).
    n = xa.shape[0]
    x0 = xa[0]
    lo, mid, hi = ra[n - 1 - m + i0:], xa[i0:], xa[i0 + m:]
    s = 0.0
    for k in range(i1 - i0):
        d = (2.0 * x0 - lo[k]) - 2.0 * mid[k] + hi[k]
        s += d * d
    return s


@jit(fastmath=True, nogil=True, inline='never')
def _right_one(xa, ra, m, i0, i1):  # pragma: no cover - compiled; tested vs numpy
    # Centres c + m > N - 1 (c - m inside): x*_{c+m} = 2 x_{N-1} - x_{2N-2-c-m}, that point
    # read ascending from the reversed phase (ra[c + m - N + 1]).
    n = xa.shape[0]
    xn = xa[n - 1]
    lo, mid, hi = xa[i0 - m:], xa[i0:], ra[i0 + m - n + 1:]
    s = 0.0
    for k in range(i1 - i0):
        d = lo[k] - 2.0 * mid[k] + (2.0 * xn - hi[k])
        s += d * d
    return s


@jit(nogil=True)
def _both_one(xa, m, i0, i1):  # pragma: no cover - compiled; tested vs numpy
    # Centres reflected at both ends (explicit factors m > (N - 1) / 2 only).
    n = xa.shape[0]
    s = 0.0
    for c in range(i0, i1):
        d = (2.0 * xa[0] - xa[m - c]) - 2.0 * xa[c] + (2.0 * xa[n - 1] - xa[2 * n - 2 - c - m])
        s += d * d
    return s


@jit(nogil=True)
def _total_blocks(xa, ra, ms, c_lo, c_hi, acc):  # pragma: no cover - compiled
    # acc[t] += sum over centres c in [c_lo, c_hi) of (x*_{c-m} - 2 x_c + x*_{c+m})^2 at
    # ms[t] (ascending), x* the reflected phase of total.reflect (SP1065 eq 25), block by
    # block as _hadamard_blocks, without its 3N-point copy: the centres whose neighbours are
    # both inside the record four factors at a time (_centred_four, as the Allan kernel), the
    # ones within m of an end with the reflected value computed on the fly.
    n = xa.shape[0]
    n_tau = ms.shape[0]
    for c0 in range(c_lo, c_hi, BLOCK):
        c1 = min(c0 + BLOCK, c_hi)
        for i0 in range(0, n_tau, 4):
            top = min(i0 + 4, n_tau)
            lo4 = hi4 = c1  # the group's common inside range [lo4, hi4)
            if top - i0 == 4:
                lo4 = max(c0, ms[i0 + 3])
                hi4 = min(c1, n - ms[i0 + 3])
                if lo4 < hi4:
                    sa, sb, sc, sd = _centred_four(xa, ms[i0], ms[i0 + 1], ms[i0 + 2],
                                                   ms[i0 + 3], lo4, hi4)
                    acc[i0] += sa
                    acc[i0 + 1] += sb
                    acc[i0 + 2] += sc
                    acc[i0 + 3] += sd
                else:
                    lo4 = hi4 = c1
            for t in range(i0, top):
                m = ms[t]
                a = max(c0, m)  # inside: [a, b)
                b = min(c1, n - m)
                s = 0.0
                if a < b:
                    if lo4 < hi4:  # what the group did not sum
                        if a < lo4:
                            s += _centred_one(xa, m, a, lo4)
                        if hi4 < b:
                            s += _centred_one(xa, m, hi4, b)
                    else:
                        s += _centred_one(xa, m, a, b)
                left = min(c1, m, n - m)
                if c0 < left:
                    s += _left_one(xa, ra, m, c0, left)
                right = max(c0, m, n - m)
                if right < c1:
                    s += _right_one(xa, ra, m, right, c1)
                both0, both1 = max(c0, n - m), min(c1, m)
                if both0 < both1:
                    s += _both_one(xa, m, both0, both1)
                acc[t] += s


def _blocked(kernel, rows, ms, lo, hi, mirrors=None):
    """
    Run a block kernel on every row of ``rows`` over [lo, hi) in (row, range) jobs: (T, A).

    ``mirrors`` (A, N), when given, go to the kernel after the row (totdev: reversed rows).
    """
    chunks = -(-8 // rows.shape[0])  # at least 8 jobs: balance on a shared machine
    cut = [lo + (hi - lo) * c // chunks for c in range(chunks + 1)]
    part = np.zeros((rows.shape[0], chunks, ms.size))

    def job(index):
        a, c = divmod(index, chunks)
        if mirrors is None:
            kernel(rows[a], ms, cut[c], cut[c + 1], part[a, c])
        else:
            kernel(rows[a], mirrors[a], ms, cut[c], cut[c + 1], part[a, c])
    map_threads(job, list(range(rows.shape[0] * chunks)))
    return part.sum(axis=1).T


def _overlapping(kind, x, ms):
    """OHVAR or TOTVAR (T, A), the overlapping sums blocked over the phase (nan: no term)."""
    n_phase = x.shape[1]
    ms = np.asarray(ms, dtype=np.int64)
    out = np.full((ms.size, x.shape[0]), np.nan)
    if kind == 'ohdev':
        ok = n_phase - 3 * ms >= 1
    else:
        ok = (ms <= n_phase - 2) & (n_phase >= 3)
    if not ok.any():
        return out
    m = ms[ok]
    if kind == 'ohdev':
        kernel, lo, hi, mirrors = _hadamard_blocks, 0, n_phase - 3 * int(m.min()), None
        norm = 6.0 * m * m * (n_phase - 3 * m)
    else:  # centres 1 .. N-2; the reflected ends read the phase backwards
        kernel, lo, hi = _total_blocks, 1, n_phase - 1
        mirrors = np.ascontiguousarray(x[:, ::-1])
        norm = 2.0 * m * m * (n_phase - 2)
    order = np.argsort(m, kind='stable')  # both kernels group ascending factors
    use = np.ascontiguousarray(m[order])
    sums = np.empty((use.size, x.shape[0]))
    sums[order] = _blocked(kernel, x, use, lo, hi, mirrors)
    out[ok] = sums / norm[:, None]
    return out


def variance(kind, x, ms):
    """Return the adev, hdev, ohdev, mdev (or tdev) or totdev variances (T, A) of x (A, N)."""
    x = np.ascontiguousarray(x, dtype=float)
    if kind in ('ohdev', 'totdev'):
        return _overlapping(kind, x, ms)
    if kind in ('adev', 'hdev'):
        return _strided(kind, x, ms)
    # mdev, tdev: one blocked pass per axis (ascending factors; nan: no inner sum).
    ms = np.asarray(ms, dtype=np.int64)
    out = np.full((ms.size, x.shape[0]), np.nan)
    ok = x.shape[1] - 3 * ms + 1 >= 1
    if ok.any():
        order = np.argsort(ms[ok], kind='stable')
        use = np.ascontiguousarray(ms[ok][order])
        sums = np.empty((x.shape[0], use.size))
        map_threads(lambda a: _modified_blocks(x[a], use, sums[a]), list(range(x.shape[0])))
        # the numpy reference's normalisation (exact int m^4), so the results equal it
        norm = np.array([2.0 * int(m) ** 4 * (x.shape[1] - 3 * int(m) + 1) for m in use])
        values = np.empty((use.size, x.shape[0]))
        values[order] = sums.T / norm[:, None]
        out[ok] = values
    return out


def _strided(kind, x, ms):
    """AVAR or HVAR, non-overlapping (T, A): one blocked pass per axis (nan: no term)."""
    from .allan_family import SPEC, terms
    d, _, norm = SPEC[kind]
    n_phase = x.shape[1]
    ms = np.asarray(ms, dtype=np.int64)
    out = np.full((ms.size, x.shape[0]), np.nan)
    ok = n_phase - d * ms >= 1
    if ok.any():
        use = np.ascontiguousarray(ms[ok])
        acc = np.zeros((x.shape[0], use.size))
        none = np.zeros(use.size + 1, dtype=np.int64)  # no points gathered
        map_threads(lambda a: _stride_blocks(x[a], use, d, acc[a], none, none, acc[a]),
                    list(range(x.shape[0])))
        count = np.array([terms(kind, n_phase, int(m)) for m in use], dtype=float)
        out[ok] = acc.T / (norm * use * use * count)[:, None]
    return out


def strided_and_alpha(kind, x, ms, dmax, alpha_range):
    """
    Return the adev or hdev variance (T, A) and noise alpha (T, A): one blocked pass per axis.

    The pass of :func:`variance` also gathers the points of the noise identification at the
    same factors (:func:`.noise_id_kernel.identify_phase` gathers them in a pass of its own);
    every factor must have a difference (``deviation``'s grids and checked taus do).
    """
    from . import noise_id_kernel
    from .allan_family import SPEC, terms
    d, _, norm = SPEC[kind]
    n_phase = x.shape[1]
    ms = np.ascontiguousarray(ms, dtype=np.int64)
    if np.any(n_phase - d * ms < 1):
        raise ValueError(f'a factor of {list(ms)} leaves no {kind} difference')
    ks, offs = noise_id_kernel.layout(n_phase - 1, ms)
    points = np.empty((x.shape[0], int(offs[-1])))
    acc = np.zeros((x.shape[0], ms.size))
    acf = np.zeros((x.shape[0], ms.size), dtype=np.int64)

    def job(a):
        _stride_blocks(x[a], ms, d, acc[a], ks, offs, points[a])
        noise_id_kernel._acf_axis(points[a], ms, ks, offs, dmax, acf[a])
    map_threads(job, list(range(x.shape[0])))
    count = np.array([terms(kind, n_phase, int(m)) for m in ms], dtype=float)
    var = acc.T / (norm * ms * ms * count)[:, None]
    return var, noise_id_kernel.alphas(points, ms, ks, offs, acf, alpha_range)
