"""
Benchmark: measuring the sensor's processing (``core/sensor/measure.py``) offline and streaming.

1. ``measure_sensor`` on 1e6 x 6 samples (the two real ADIS16405 runs when the shared data
   are there, else the thesis 3DM-GX3-25 model rounded to the ADIS's LSBs) and on 10 h at
   100 Hz (3.6e7 x 6, an ADIS-like simulation, against its first 1e6 rows: the cost does not
   grow with the length beyond MAX_EXAMINED = 2^18 samples per axis).  Best of 5, wall and
   CPU seconds of this process.  Goals: under 0.15 s on 1e6 x 6; 10 h no more than 0.05 s
   above 1e6, and its CPU about 0.05 s (what ``analyze`` of the 10-h MCAP may spend on it).
2. ``SensorAccumulator`` fed 50 rows at a time (the live node's drain batch) at 100 Hz:
   microseconds per 6-axis row, and ``report()``.

Usage: ``python bench/bench_sensor.py``.
"""

import math
import os
from pathlib import Path
import sys
import time

from benchlib import best_of, goal, header
from imu_allan.core.model import thesis_gx3_25_model
from imu_allan.core.sensor.measure import MAX_EXAMINED, measure_sensor, SensorAccumulator
from imu_allan.core.simulation.simulate import simulate
import numpy as np

RATE = 100.0
SHARED = Path(os.environ.get('IMU_ALLAN_SHARED',
                             Path(__file__).resolve().parents[1].parent / 'shared'))


def _record():
    """1e6 x 6 samples in SI: the ADIS16405 run 2 if present, else a rounded simulation."""
    path = SHARED / 'data' / 'adis16405' / 'adis_16405_run2.npz'
    if path.is_file():
        d = np.load(path)
        return 'ADIS16405 run 2', np.hstack([d['gyro_deg_s'] * (math.pi / 180.0),
                                             d['accel_g'] * 9.80665])
    data = simulate(thesis_gx3_25_model(), 1_000_000, RATE, seed=1)
    lsb = np.array([0.05 * math.pi / 180.0] * 3 + [3.33e-3 * 9.80665] * 3)
    return 'simulated, rounded', np.round(data / lsb) * lsb


def _ten_hours():
    """
    Return 10 h x 6 at 100 Hz like the ADIS16405, none of it repeated.

    A tiled record makes Welch segments that share samples, and so lines out of noise.  Per
    axis white noise through [1, 0.2] (rho_1 = 0.19), a random walk, rounded to the
    ADIS's LSBs, as float64; generated in blocks of an hour.
    """
    n, hour = 36 * 1_000_000, 360_000
    lsb = np.array([0.05 * math.pi / 180.0] * 3 + [3.33e-3 * 9.80665] * 3)
    sigma = np.array([7.0] * 3 + [1.2] * 3) * lsb
    out = np.empty((n, 6))
    rng = np.random.default_rng(10)
    walk = np.zeros(6)
    for i in range(0, n, hour):
        w = rng.standard_normal((hour + 1, 6))
        block = (w[1:] + 0.2 * w[:-1]) * (sigma / math.sqrt(1.04))
        steps = np.cumsum(rng.standard_normal((hour, 6)) * sigma * 1e-3, axis=0) + walk
        walk = steps[-1]
        out[i:i + hour] = np.round((block + steps) / lsb) * lsb
    return out


def bench_offline():
    """Best-of-5 cost of measure_sensor on 1e6 x 6 and on 10 h x 6."""
    name, data = _record()
    measure_sensor(data, RATE)     # first call: caches, page faults
    _, wall, cpu = best_of(lambda: measure_sensor(data, RATE), 5)
    print(f'measure_sensor, {name}, {data.shape[0]} x 6: {wall:.3f} s wall, {cpu:.3f} s CPU '
          f'(at most {MAX_EXAMINED} samples per axis examined)')
    goal(f'1e6 x 6 under 0.15 s (wall {wall:.3f} s, CPU {cpu:.3f} s)', wall < 0.15)
    report = measure_sensor(data, RATE)
    for axis, ax in report.axes.items():
        print(f'  {axis:8s} LSB {ax.resolution:.6g}  repeats {ax.repeated_fraction:.3f}  '
              f'rho_1 {ax.lag_correlation[0]:.3f}  filter {ax.filter_length}  '
              f'lines {len(ax.lines)}  humps {len(ax.humps)}')
    long = _ten_hours()
    short = long[:1_000_000]
    _, wall1, cpu1 = best_of(lambda: measure_sensor(short, RATE), 5)
    _, wall10, cpu10 = best_of(lambda: measure_sensor(long, RATE), 5)
    print(f'measure_sensor, ADIS-like simulation: first 1e6 x 6 {wall1:.3f} s wall, '
          f'{cpu1:.3f} s CPU; 10 h ({long.shape[0]} x 6) {wall10:.3f} s wall, '
          f'{cpu10:.3f} s CPU')
    goal(f'10 h x 6 under 0.05 s more than 1e6 x 6 (wall {wall10 - wall1:+.3f} s, '
         f'CPU {cpu10 - cpu1:+.3f} s)', wall10 - wall1 < 0.05)
    goal(f'10 h x 6 adds at most ~0.05 s to analyze (CPU {cpu10:.3f} s)', cpu10 < 0.075)


def bench_streaming():
    """Per-row cost of SensorAccumulator in 50-row batches, and of report()."""
    _, data = _record()
    data = data[:360_000]           # one hour at 100 Hz
    acc = SensorAccumulator(RATE, ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y',
                                   'accel_z'))
    w0, c0 = time.perf_counter(), time.process_time()
    for i in range(0, data.shape[0], 50):
        acc.update(data[i:i + 50])
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    n = data.shape[0]
    print(f'SensorAccumulator, {n} rows x 6 in 50-row blocks: {wall / n * 1e6:.2f} us wall, '
          f'{cpu / n * 1e6:.2f} us CPU per row')
    _, wall_r, cpu_r = best_of(acc.report, 3)
    print(f'SensorAccumulator.report(): {wall_r:.3f} s wall, {cpu_r:.3f} s CPU')


def main():
    """Run both sections."""
    header('bench_sensor')
    bench_offline()
    bench_streaming()


if __name__ == '__main__':
    sys.exit(main())
