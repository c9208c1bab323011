"""Benchmark: reading sensor_msgs/Imu from bags, generic deserializer vs bulk fast path.

Writes a synthetic 1,000,000-message Imu bag (MCAP and sqlite3 rosbag2, and a 200,000-message
ROS 1 bag) into a temporary folder once, then times ``read_bag(..., fast=False)`` (rosbags'
per-message deserializer and the message -> numpy adapter) and ``read_bag(..., fast=True)``
(bulk numpy decoding). Prints messages/s for each and the speed-up, and checks both give the
same numbers. Usage: ``python bench/bench_read.py [N]``.
"""

from functools import partial
from pathlib import Path
import sys
import tempfile
import time

import numpy as np

from imu_allan.io.bag_reader import read_bag
from imu_allan.io.bag_writer import write_imu_bag
from imu_allan.io.samples import Samples


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main():
    """Run the benchmark and print one line per storage and path."""
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
    n_ros1 = min(n, 200_000)
    rng = np.random.default_rng(0)
    t = 1.7e9 + np.arange(n) / 400.0
    data = rng.normal(0.0, 0.01, size=(n, 6))
    data[:, 5] += 9.81
    print(f'bench_read: {n} Imu messages (324 B CDR, frame_id imu_link, 400 Hz stamps)')
    with tempfile.TemporaryDirectory(prefix='bench_read_') as tmp:
        cases = [('mcap', n), ('sqlite3', n), ('ros1', n_ros1)]
        for storage, count in cases:
            name = f'bag_{storage}' + ('.bag' if storage == 'ros1' else '')
            path = Path(tmp) / name
            samples = Samples(t=t[:count], data=data[:count])
            _, dt_w = _timed(partial(write_imu_bag, path, samples, storage=storage))
            print(f'  {storage:8s} write {count} msgs: {dt_w:6.2f} s '
                  f'({count / dt_w / 1e3:7.0f} k msg/s)')
            fast, dt_f = _timed(partial(read_bag, path, fast=True))
            gen, dt_g = _timed(partial(read_bag, path, fast=False))
            same = np.array_equal(fast.t, gen.t) and np.array_equal(fast.data, gen.data)
            print(f'  {storage:8s} generic: {dt_g:6.2f} s ({count / dt_g / 1e3:7.0f} k msg/s)   '
                  f'fast: {dt_f:6.3f} s ({count / dt_f / 1e6:5.2f} M msg/s)   '
                  f'speed-up x{dt_g / dt_f:5.1f}   identical: {same}')
            fast2, dt_f2 = _timed(partial(read_bag, path, fast=True))
            print(f'  {storage:8s} fast (second run, warm cache): {dt_f2:6.3f} s '
                  f'({count / dt_f2 / 1e6:5.2f} M msg/s)')
            path_size = sum(f.stat().st_size for f in Path(tmp).rglob('*') if f.is_file())
            del fast, gen, fast2
            if storage != 'ros1':
                zpath = Path(tmp) / f'bag_{storage}_zstd'
                if storage == 'mcap':
                    write_imu_bag(zpath, samples, storage='mcap', compress=True)
                    fz, dt_z = _timed(partial(read_bag, zpath, fast=True))
                    print(f'  mcap+zstd fast: {dt_z:6.3f} s ({count / dt_z / 1e6:5.2f} M msg/s)')
                    del fz
            _ = path_size


if __name__ == '__main__':
    main()
