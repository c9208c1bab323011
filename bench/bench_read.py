"""
Benchmark: reading sensor_msgs/Imu from bags, generic deserializer vs bulk fast path.

Writes a synthetic Imu recording (1,000,000 messages as MCAP and sqlite3 rosbag2, 200,000 as
a ROS 1 bag; 324-byte CDR, frame_id ``imu_link``, 400 Hz stamps) into a temporary folder once,
then times ``read_bag(..., fast=False)`` (rosbags' per-message deserializer and the message ->
numpy adapter) and ``read_bag(..., fast=True)`` (direct storage reading and bulk numpy
decoding), checks both give identical numbers and prints messages/s and the speed-up. Rates
are given per wall-clock second and per CPU second of this process (the machine is shared,
CPU time is the steadier figure). Usage: ``python bench/bench_read.py [N] [STORAGE ...]``
(STORAGE: mcap, mcap+zstd, sqlite3, ros1; all by default).
"""

from functools import partial
from pathlib import Path
import sys
import tempfile
import time

from benchlib import goal, header
from imu_allan.formats.bag_reader import read_bag
from imu_allan.formats.bag_writer import write_imu_bag
from imu_allan.formats.samples import Samples
import numpy as np

#: Goals of the fast path, messages per wall-clock second.
GOALS = {'mcap': 1e6, 'sqlite3': 2.5e6}


def _timed(fn, repeat=1):
    """Run fn; return (result, best wall s, best CPU s)."""
    best_w = best_c = float('inf')
    out = None
    for _ in range(repeat):
        out = None
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best_w = min(best_w, time.perf_counter() - w0)
        best_c = min(best_c, time.process_time() - c0)
    return out, best_w, best_c


def main():
    """Run the benchmark and print one line per storage and path."""
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    rng = np.random.default_rng(0)
    t = 1.7e9 + np.arange(n) / 400.0
    data = rng.normal(0.0, 0.01, size=(n, 6))
    data[:, 5] += 9.81
    header('bench_read')
    print('bench_read: Imu messages, 324 B CDR each; rates in messages/s (wall | CPU)')
    with tempfile.TemporaryDirectory(prefix='bench_read_') as tmp:
        cases = [('mcap', n, False), ('mcap', n, True), ('sqlite3', n, False),
                 ('ros1', min(n, 200_000), False)]
        chosen = set(sys.argv[2:])
        for storage, count, zstd in cases:
            label = storage + ('+zstd' if zstd else '')
            if chosen and label not in chosen:
                continue
            name = f'bag_{label}' + ('.bag' if storage == 'ros1' else '')
            path = Path(tmp) / name
            samples = Samples(t=t[:count], data=data[:count])
            _, w, _ = _timed(partial(write_imu_bag, path, samples, storage=storage,
                                     compress=zstd))
            print(f'  {label:10s} {count:8d} msgs written in {w:5.1f} s')
            fast, fw, fc = _timed(partial(read_bag, path, fast=True), repeat=3)
            if zstd:
                print(f'  {label:10s} fast    {count / fw / 1e6:5.2f} M | '
                      f'{count / fc / 1e6:5.2f} M')
                continue
            gen, gw, gc = _timed(partial(read_bag, path, fast=False))
            same = np.array_equal(fast.t, gen.t) and np.array_equal(fast.data, gen.data)
            print(f'  {label:10s} generic {count / gw / 1e3:5.0f} k | {count / gc / 1e3:5.0f} k   '
                  f'fast {count / fw / 1e6:5.2f} M | {count / fc / 1e6:5.2f} M   '
                  f'speed-up x{gw / fw:4.0f} | x{gc / fc:4.0f}   identical: {same}')
            if storage in GOALS:
                goal(f'read: {label} fast path {count / fw / 1e6:.2f} M messages/s wall '
                     f'({count / fc / 1e6:.2f} M/s CPU; goal >= {GOALS[storage] / 1e6:g} M/s, '
                     'identical numbers)', same and count / fw >= GOALS[storage])
            del fast, gen


if __name__ == '__main__':
    main()
