"""
Benchmark: every deviation kind of ``imu_allan.deviation`` against the matching allantools one.

1.7 million samples x 6 axes (4.7 h at 100 Hz, the thesis's largest data set), each kind's
default grid (10 per decade up to Stable32's stop ratio; oadev up to T/10).  Ours is timed
with the noise identification, EDF and 68.3 % intervals (allantools returns none of these);
both run in this process on the same data, and the deviations must agree to 1e-9 relative
(ours uncorrected: allantools applies no bias correction).

allantools' mtotdev, htotdev and theo1 loop over every window in Python (O(N m) interpreted
per averaging time): on 1.7 M samples one axis would take hours.  For these the speed-up is
measured on 20 000 samples, one axis, m = 2, 4, 8, 16 (both exact there), and our time on the
full 1.7 M x 6 is printed beside it (window starts thinned on long records, :mod:`total_kernel`).

``--rounds R`` times each kind R times, ours then allantools', and quotes the median of the R
paired ratios (with their range): the machine is shared, and a pair taken back to back sees
the same conditions.  ``--load P`` starts P busy processes of its own for the whole run (each
a pure-Python ``while True: pass``, one core's worth; started and stopped by this script), so
that "under load" means the same thing from run to run on top of whatever else runs.  Where
the kernel groups tasks by session (autogroup), they take from our share and allantools'
alike, and load from other sessions brings the ratio down to the ratio of CPU times
(docs/benchmarks.md).

Goals: >= 10x allantools per kind (adev, hdev: >= 3x), same numbers, quiet and under load.
"""

import argparse
import statistics
import subprocess
import sys
import time

import allantools
from benchlib import goal, header, load
from imu_allan import deviation, simulate, thesis_gx3_25_model
from imu_allan.core.allan import estimate as allan
from imu_allan.core.allan.estimate import _phase
from imu_allan.core.deviations import api
import numpy as np

N_SAMPLES = 1_700_000
RATE = 100.0
AT = {'adev': allantools.adev, 'oadev': allantools.oadev, 'mdev': allantools.mdev,
      'tdev': allantools.tdev, 'hdev': allantools.hdev, 'ohdev': allantools.ohdev,
      'totdev': allantools.totdev, 'mtotdev': allantools.mtotdev,
      'htotdev': allantools.htotdev, 'theo1': allantools.theo1}
SLOW = ('mtotdev', 'htotdev', 'theo1')


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def raw_dev(kind, data, ms):
    """Our uncorrected deviation (what allantools computes) at factors ``ms``."""
    dev = np.sqrt(api.raw_variance(kind, _phase(data), ms, data))
    if kind == 'tdev':
        dev = dev * (ms / RATE)[:, None] / np.sqrt(3.0)
    return dev


def one_round(kind, data):
    """
    Time ours and allantools' once, back to back: (ratio, ours s, theirs s, rel. diff., text).

    The slow kinds: the ratio on 20 000 x 1 at m = 2..16, our full-record time beside it.
    """
    result, ours_w = timed(lambda: deviation(data, RATE, kind))
    factor = 0.75 if kind == 'theo1' else 1.0
    if kind in SLOW:
        small = data[:20_000, :1]
        ms = np.array([2, 4, 8, 16])
        _, small_w = timed(lambda: deviation(small, RATE, kind, taus=ms * factor / RATE))
        theirs, theirs_w = timed(lambda: np.column_stack([
            AT[kind](small[:, 0], rate=RATE, data_type='freq', taus=ms / RATE)[1]]))
        rel = float(np.max(np.abs(raw_dev(kind, small, ms) / theirs - 1.0)))
        text = (f'1.7 M x 6, {result.m.size} averaging times, ours {ours_w:.2f} s; 20 000 x 1 '
                f'at m = 2..16: ours {small_w:.3f} s, allantools {theirs_w:.2f} s')
        return theirs_w / small_w, small_w, theirs_w, rel, text
    taus = result.m / RATE
    theirs, theirs_w = timed(lambda: np.column_stack([
        AT[kind](data[:, j], rate=RATE, data_type='freq', taus=taus)[1]
        for j in range(data.shape[1])]))
    rel = float(np.max(np.abs(raw_dev(kind, data, result.m) / theirs - 1.0)))
    text = (f'1.7 M x 6, {result.m.size} averaging times: ours {ours_w:.2f} s (with noise ID, '
            f'EDF, intervals), allantools {theirs_w:.2f} s')
    return theirs_w / ours_w, ours_w, theirs_w, rel, text


def busy(count):
    """Start ``count`` busy processes (one core's worth each); the caller stops them."""
    return [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(count)]


def main(argv=None):
    """Run the kinds asked for, print the timings and ratios, and the goals."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--kinds', default=','.join(AT), help='comma-separated kinds')
    parser.add_argument('--rounds', type=int, default=1, help='paired rounds per kind')
    parser.add_argument('--load', type=int, default=0,
                        help='busy processes started for the run (each one core)')
    args = parser.parse_args(argv)
    kinds = [k for k in args.kinds.split(',') if k]
    header('bench_deviations')
    data = simulate(thesis_gx3_25_model(), N_SAMPLES, RATE, seed=1)
    data[:, 5] += 9.80665
    # Every kind's compiled kernels loaded from numba's disk cache (or compiled) once before
    # timing, as in any process that has computed a deviation before: on 5 000 samples with
    # the numpy threshold lowered so that the short calls take the compiled paths.  The
    # loading itself, once per process, is printed.
    small_work, allan.SMALL_WORK = allan.SMALL_WORK, 0
    _, load_w = timed(lambda: [deviation(data[:5000], RATE, kind) for kind in kinds])
    allan.SMALL_WORK = small_work
    print(f'compiled kernels of every kind loaded once per process: {load_w:.2f} s')
    helpers = busy(args.load)
    try:
        if helpers:
            time.sleep(1.0)
            print(f'{len(helpers)} busy process(es) of this benchmark running; {load()}')
        for kind in kinds:
            rounds = [one_round(kind, data) for _ in range(args.rounds)]
            ratios = [r[0] for r in rounds]
            ratio = statistics.median(ratios)
            rel = max(r[3] for r in rounds)
            for r in rounds:
                print(f'{kind}: {r[4]}; {r[0]:.1f}x ({load()})', flush=True)
            spread = (f' (median of {len(ratios)} paired rounds, {min(ratios):.1f}-'
                      f'{max(ratios):.1f}x; ours {statistics.median(r[1] for r in rounds):.3f}'
                      f' s, allantools {statistics.median(r[2] for r in rounds):.2f} s)'
                      if len(ratios) > 1 else '')
            need = 3.0 if kind in ('adev', 'hdev') else 10.0
            goal(f'deviations {kind}: {ratio:.1f}x allantools{spread}, max relative '
                 f'difference {rel:.1e} (goal >= {need:g}x, <= 1e-9; load added: '
                 f'{args.load} busy process(es))', ratio >= need and rel <= 1e-9)
    finally:
        for helper in helpers:
            helper.kill()
            helper.wait()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
