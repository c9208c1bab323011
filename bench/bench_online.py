"""
Benchmark: the online Allan estimator and the allan node at 1 kHz x 6 axes.

Sections (each prints its numbers):

1. ``estimator``: per-sample cost of :class:`StreamingAllan`, of the whole online pipeline
   (stamp checks + stationarity gate + estimator) and of the change test, fed in 50-sample
   batches (the node's drain period at 1 kHz), the cost of ``result()`` and of the fit, and
   the memory (fixed) for max_tau = 10,000 s.
2. ``accuracy``: the strided factors (m > stride_base) against the fully overlapping
   estimator on simulated white, flicker and random-walk noise: mean ratio (bias) and the
   ratio of the spreads (how much wider an honest interval would be).
3. ``node``: CPU share of the built ``allan`` executable (change test on by default, and
   off) while this process publishes 6-axis
   Imu messages at 1 kHz, side by side with a plain rclpy subscriber that does nothing, and the
   node's publish-cycle time (from its diagnostics); also with ``covariance_topic`` set (every
   message republished with live covariances, received here).  Needs the colcon-built package.
4. ``covariance``: cost of patching the covariance diagonals in 50-message batches of CDR
   bytes (:func:`imu_allan.formats.imu_cdr.set_covariance_diagonals`).
5. ``plot``: render time per publish cycle of the live figure (``imu/allan_plot/compressed``).
6. ``kinds``: streaming MDEV and OHDEV (``estimators``) on 10^7 samples at 1 kHz with a 1 g
   offset against a long-double batch reference (relative difference) and their cost.

The ``estimator`` and ``node`` sections also run with ``estimators`` oadev,mdev,ohdev;
``node_estimators`` runs the node without and with them, alternately, twice.

Usage: ``python bench/bench_online.py [estimator|accuracy|node|covariance|plot|kinds|
node_estimators ...]`` (default: all but node_estimators).
"""

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')  # as the nodes do (see nodes/allan.py)

import math  # noqa: E402, I100 - after the environment setting above
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from benchlib import header  # noqa: E402
from imu_allan.core.allan.estimate import allan_deviation  # noqa: E402
from imu_allan.core.live.online import OnlineAllan  # noqa: E402
from imu_allan.core.live.streaming import StreamingAllan  # noqa: E402
from imu_allan.core.model import NoiseModel, thesis_gx3_25_model  # noqa: E402
from imu_allan.core.simulation.simulate import simulate  # noqa: E402
import numpy as np  # noqa: E402


def bench_estimator():
    """Per-sample cost and memory at 1 kHz x 6 axes."""
    rate = 1000.0
    n = 600_000  # 10 min
    data = simulate(thesis_gx3_25_model(), n, rate, seed=1)
    data[:, 5] += 9.80665
    t = np.arange(n) / rate
    batch = 50
    print(f'estimator: {n} samples x 6 axes at {rate:g} Hz, fed {batch} at a time')
    est = StreamingAllan(rate, max_tau=10000.0)
    start = time.perf_counter()
    for i in range(0, n, batch):
        est.update(data[i:i + batch])
    dt = time.perf_counter() - start
    print(f'  StreamingAllan: {dt / n * 1e6:6.2f} us per 6-axis sample '
          f'({100 * dt / (n / rate):.2f} % of one core at {rate:g} Hz); '
          f'{est.ms.size} averaging factors up to {est.ms[-1] / rate:g} s; '
          f'memory {est.memory_bytes() / 1024:.0f} KiB (fixed)')
    pipe = OnlineAllan(rate, max_tau=10000.0)
    start = time.perf_counter()
    for i in range(0, n, batch):
        pipe.feed(t[i:i + batch], data[i:i + batch])
    dt = time.perf_counter() - start
    print(f'  OnlineAllan (stamps + gate + estimator): {dt / n * 1e6:6.2f} us per sample '
          f'({100 * dt / (n / rate):.2f} % of one core); memory '
          f'{pipe.memory_bytes() / 1024:.0f} KiB (fixed)')
    from imu_allan.core.live.change_monitor import ChangeMonitor
    from imu_allan.core.units import AXES
    monitor = ChangeMonitor(rate, 600.0, AXES)
    start = time.perf_counter()
    for i in range(0, n, batch):
        monitor.feed(t[i:i + batch], data[i:i + batch])
    dt = time.perf_counter() - start
    print(f'  ChangeMonitor (change test, window 600 s): {dt / n * 1e6:6.2f} us per sample '
          f'({100 * dt / (n / rate):.2f} % of one core); {monitor.ms.size} averaging factors; '
          f'memory {monitor.memory_bytes() / 1024:.0f} KiB (fixed)')
    start = time.perf_counter()
    result = pipe.result()
    dt_r = time.perf_counter() - start
    start = time.perf_counter()
    pipe.fit(result)
    dt_f = time.perf_counter() - start
    print(f'  result(): {dt_r * 1e3:.1f} ms ({result.tau.size} taus x 6 axes, EDF + intervals);'
          f' fit: {dt_f * 1e3:.0f} ms (automatic term selection, 6 axes)')
    kinds = 'oadev,mdev,ohdev'
    est = StreamingAllan(rate, max_tau=10000.0, estimators=kinds)
    start = time.perf_counter()
    for i in range(0, n, batch):
        est.update(data[i:i + batch])
    dt = time.perf_counter() - start
    print(f'  StreamingAllan estimators={kinds}: {dt / n * 1e6:6.2f} us per 6-axis sample '
          f'({100 * dt / (n / rate):.2f} % of one core); memory '
          f'{est.memory_bytes() / 1024:.0f} KiB (fixed)')
    pipe = OnlineAllan(rate, max_tau=10000.0, estimators=kinds)
    start = time.perf_counter()
    for i in range(0, n, batch):
        pipe.feed(t[i:i + batch], data[i:i + batch])
    dt = time.perf_counter() - start
    print(f'  OnlineAllan estimators={kinds}: {dt / n * 1e6:6.2f} us per sample '
          f'({100 * dt / (n / rate):.2f} % of one core); memory '
          f'{pipe.memory_bytes() / 1024:.0f} KiB (fixed)')


def _kind_reference(y, m, kind):
    """MVAR / OHVAR sum of squares and count (SP1065 eq. 14 / 18), long double, de-meaned."""
    y = y.astype(np.longdouble)
    y = y - y.mean()
    x = np.zeros(y.size + 1, np.longdouble)
    x[1:] = np.cumsum(y)
    if kind == 'ohdev':
        d = x[3 * m:] - 3 * x[2 * m:-m] + 3 * x[m:-2 * m] - x[:-3 * m]
    else:
        d2 = x[2 * m:] - 2 * x[m:-m] + x[:-2 * m]
        c = np.zeros(d2.size + 1, np.longdouble)
        c[1:] = np.cumsum(d2)
        d = c[m:] - c[:-m]
    return float((d * d).sum()), d.size


def bench_kinds(n=10_000_000, rate=1000.0):
    """Streaming MDEV / OHDEV on 10^7 samples with a 1 g offset: precision and cost."""
    rng = np.random.default_rng(3)
    # accelerometer-like: 1 g, white noise, a slow rate random walk (curvature in S)
    y = 9.80665 + 0.025 * rng.standard_normal(n) + np.cumsum(1e-6 * rng.standard_normal(n))
    taus = [0.001, 0.01, 0.1, 1.0, 10.0, 100.0]
    est = StreamingAllan(rate, axes=('accel_z',), taus=taus, exact=True,
                         estimators='mdev,ohdev', frame=65536)
    start = time.process_time()
    for i in range(0, n, 1_000_000):
        est.update(y[i:i + 1_000_000, None])
    dt = time.process_time() - start
    print(f'kinds: {n} samples at {rate:g} Hz, 1 g offset, exact at tau {taus} s: streaming '
          f'{dt:.1f} s CPU (1 axis, 3 kinds); raw phase sum reaches {n * n * 9.8 / 2:.1e}')
    for kind in ('mdev', 'ohdev'):
        ms, _, acc, cnt = est.sums(kind=kind)
        worst = 0.0
        for f, m in enumerate(ms):
            ref, count = _kind_reference(y, int(m), kind)
            assert cnt[f, 0] == count
            worst = max(worst, abs(acc[f, 0] / ref - 1))
        print(f'  {kind}: largest relative difference to the long-double reference '
              f'{worst:.1e}')


def bench_accuracy(runs=100):
    """Strided long-tau factors vs the fully overlapping estimator on simulated noise."""
    rate = 100.0
    n = 2 ** 17
    taus = np.array([5.12, 20.48, 81.92, 131.07])
    models = {
        'white (N)': {'gyro_x': {'white_noise': 1e-3}},
        'flicker (B)': {'gyro_x': {'bias_instability': 1e-3}},
        'random walk (K)': {'gyro_x': {'rate_random_walk': 1e-4}},
    }
    print(f'accuracy: strided vs full overlapping AVAR, {runs} runs of {n} samples at '
          f'{rate:g} Hz per noise type; per run the strided/full ratio; spread = std(strided) '
          f'/ std(full) across runs')
    for base in (256, 16):
        for name, terms in models.items():
            model = NoiseModel(terms)
            ratios, full, strided = [], [], []
            for seed in range(runs):
                x = simulate(model, n, rate, seed=seed)
                est = StreamingAllan(rate, axes=('gyro_x',), taus=taus, frame=8192,
                                     stride_base=base)
                est.update(x)
                res = est.result(min_clusters=1)
                ref = allan_deviation(x, rate, taus=res.tau)
                ratios.append(res.avar[:, 0] / ref.avar[:, 0])
                full.append(ref.avar[:, 0])
                strided.append(res.avar[:, 0])
            ratios, full, strided = map(np.array, (ratios, full, strided))
            spread = strided.std(axis=0) / full.std(axis=0)
            for j, m in enumerate(res.m):
                s = est.strides[np.searchsorted(est.ms, m)]
                print(f'  base {base:3d} {name:16s} m={m:6d} stride {s:4d}: ratio mean '
                      f'{ratios[:, j].mean():.5f} (rms {ratios[:, j].std():.5f}), spread '
                      f'{spread[j]:.4f} -> ADEV interval '
                      f'{100 * (math.sqrt(spread[j]) - 1):+.2f} % wider')


_EMPTY_SUBSCRIBER = """
import rclpy
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu
rclpy.init()
node = rclpy.create_node('empty_subscriber')
node.create_subscription(Imu, 'imu/data_raw', lambda m: None, qos_profile_sensor_data)
try:
    rclpy.spin(node)
except BaseException:
    pass
"""


def _cpu_seconds(pid):
    with open(f'/proc/{pid}/stat') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def bench_node(seconds=35.0, rate=1000.0, cases=None):
    """
    CPU share of the allan node vs an empty subscriber at 1 kHz, and its cycle time.

    ``cases``: labels of the configurations to run, in that order (repeats allowed); default
    all once.
    """
    try:
        from diagnostic_msgs.msg import DiagnosticArray
        import rclpy
        from sensor_msgs.msg import Imu
        sys.path.insert(0, os.path.join(os.path.dirname(__file__), '..', 'test'))
        from conftest import executable
        exe = executable('allan')
    except (ImportError, FileNotFoundError, LookupError) as exc:
        print(f'node: skipped ({exc}); build with make first')
        return
    env = dict(os.environ, ROS_DOMAIN_ID=str(os.getpid() % 100 + 100))
    os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
    data = simulate(thesis_gx3_25_model(), int(seconds * rate) + 1000, rate, seed=3)
    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    from rclpy.qos import qos_profile_sensor_data
    pub = node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    cycles = []

    def on_diag(msg):
        for status in msg.status:
            if status.name.endswith('IMU stream'):
                values = {kv.key: kv.value for kv in status.values}
                if values.get('cycle_total_s', 'nan') != 'nan':
                    cycles.append((float(values['cycle_total_s']),
                                   float(values['cycle_max_step_s']),
                                   float(values['cycle_wall_s'])))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, 10)
    print(f'node: {seconds:g} s of 6-axis Imu at {rate:g} Hz (best effort) per subscriber')
    configs = (('empty rclpy subscriber', [sys.executable, '-c', _EMPTY_SUBSCRIBER]),
               ('allan node (publish_period 10 s)',
                [exe, '--ros-args', '-p', f'rate_hz:={rate}',
                 '-p', 'publish_period:=10.0']),
               ('allan node, change test off',
                [exe, '--ros-args', '-p', f'rate_hz:={rate}',
                 '-p', 'publish_period:=10.0', '-p', 'change_window_s:=0.0']),
               ('allan node + covariance_topic',
                [exe, '--ros-args', '-p', f'rate_hz:={rate}',
                 '-p', 'publish_period:=10.0', '-p', 'covariance_topic:=imu/data_cov']),
               ('allan node estimators=oadev,mdev,ohdev',
                [exe, '--ros-args', '-p', f'rate_hz:={rate}',
                 '-p', 'publish_period:=10.0', '-p', 'estimators:=oadev,mdev,ohdev']))
    if cases is not None:
        configs = [c for label in cases for c in configs if c[0] == label]
    for label, cmd in configs:
        cycles.clear()
        # the republished stream goes to a subscriber in its own process (as an estimator)
        reader = subprocess.Popen(
            [sys.executable, '-c', _EMPTY_SUBSCRIBER, '--ros-args', '-r',
             'imu/data_raw:=imu/data_cov'], env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL) if 'covariance' in label else None
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + 30
            while (pub.get_subscription_count() == 0 or (
                    reader is not None and node.count_subscribers('imu/data_cov') == 0)) \
                    and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
            time.sleep(1.0)
            cpu0, wall0 = _cpu_seconds(proc.pid), time.monotonic()
            msg = Imu()
            i, period = 0, 1.0 / rate
            next_t = time.monotonic()
            while time.monotonic() - wall0 < seconds:
                # Publish in bursts every 10 ms: a 1 kHz stream as a USB IMU delivers it.
                burst = int(rate * 0.01)
                for _ in range(burst):
                    row = data[i % data.shape[0]]
                    stamp = wall0 + i * period
                    msg.header.stamp.sec = int(stamp)
                    msg.header.stamp.nanosec = int((stamp - int(stamp)) * 1e9)
                    w, a = msg.angular_velocity, msg.linear_acceleration
                    w.x, w.y, w.z, a.x, a.y, a.z = (float(v) for v in row)
                    pub.publish(msg)
                    i += 1
                next_t += burst * period
                rclpy.spin_once(node, timeout_sec=max(0.0, next_t - time.monotonic()))
            cpu1, wall1 = _cpu_seconds(proc.pid), time.monotonic()
            share = 100.0 * (cpu1 - cpu0) / (wall1 - wall0)
            extra = ''
            if cycles:
                arr = 1e3 * np.array(cycles)
                med, worst = np.median(arr, axis=0), np.max(arr, axis=0)
                extra = (f'; publish cycle ({len(cycles)} cycles, median / worst): work '
                         f'{med[0]:.0f} / {worst[0]:.0f} ms in steps of at most {med[1]:.0f} / '
                         f'{worst[1]:.0f} ms, spread over {med[2]:.0f} / {worst[2]:.0f} ms')
            print(f'  {label:40s}: {share:5.1f} % of one core ({i / (wall1 - wall0):.0f} msg/s '
                  f'sent){extra}')
        finally:
            for p in (proc, reader):
                if p is not None:
                    p.terminate()
                    p.wait(timeout=10)
            # DDS still lists the ended node's subscription for a while: wait until it is gone,
            # or the next case's timing starts while that node is still starting (imports)
            deadline = time.monotonic() + 30
            while pub.get_subscription_count() > 0 and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.try_shutdown()


def bench_covariance(n=200_000, batch=50):
    """Per-message cost of patching covariance diagonals in CDR bytes (the node's republish)."""
    from imu_allan.formats.imu_cdr import encode_imu, set_covariance_diagonals
    rows, _ = encode_imu(np.arange(n) / 1000.0, np.zeros((n, 6)))
    blobs = [r.tobytes() for r in rows]
    variances = np.full(6, 1e-4)
    start = time.perf_counter()
    for i in range(0, n, batch):
        set_covariance_diagonals(blobs[i:i + batch], variances)
    dt = time.perf_counter() - start
    print(f'covariance: set_covariance_diagonals in batches of {batch}: {dt / n * 1e6:.2f} us '
          f'per message ({100 * dt / (n / 1000.0):.2f} % of one core at 1 kHz)')


def bench_plot(cycles=10):
    """
    Render time of the live figure per publish cycle (the allan node's worker thread).

    A 1 h, 100 Hz thesis-model estimate with the automatic fit; the figure object is kept
    between cycles as in the node, so the first render (figure set-up) is shown apart.
    Wall time and the rendering thread's CPU time (the machine is shared).
    """
    from imu_allan.report.plots import LiveFigure
    rate, n = 100.0, 360_000
    data = simulate(thesis_gx3_25_model(), n, rate, seed=2)
    pipe = OnlineAllan(rate)
    pipe.feed(np.arange(n) / rate, data)
    result = pipe.result()
    fitted = pipe.fit(result)
    figure = LiveFigure()
    start = time.perf_counter()
    png = figure.render(result, fitted, 'bench')
    first = time.perf_counter() - start
    walls, cpus = [], []
    for _ in range(cycles):
        wall, cpu = time.perf_counter(), time.thread_time()
        png = figure.render(result, fitted, 'bench')
        cpus.append(time.thread_time() - cpu)
        walls.append(time.perf_counter() - wall)
    width, height = figure.size_px
    print(f'plot: live figure {width}x{height} px, PNG {len(png) / 1024:.0f} KiB, '
          f'{result.tau.size} taus x 6 axes: first render {first * 1e3:.0f} ms; then per cycle '
          f'median {np.median(walls) * 1e3:.0f} ms wall (min {min(walls) * 1e3:.0f}), '
          f'{np.median(cpus) * 1e3:.0f} ms CPU (min {min(cpus) * 1e3:.0f}); goal < 150 ms')


def bench_node_estimators():
    """Run the allan node without and with estimators=oadev,mdev,ohdev, alternately, twice."""
    plain, kinds = 'allan node (publish_period 10 s)', 'allan node estimators=oadev,mdev,ohdev'
    bench_node(cases=(plain, kinds, plain, kinds))


def main():
    """Run the selected sections (all by default)."""
    header('bench_online')
    sections = sys.argv[1:] or ['estimator', 'accuracy', 'node', 'covariance', 'plot', 'kinds']
    for section in sections:
        {'estimator': bench_estimator, 'accuracy': bench_accuracy, 'node': bench_node,
         'covariance': bench_covariance, 'plot': bench_plot, 'kinds': bench_kinds,
         'node_estimators': bench_node_estimators}[section]()


if __name__ == '__main__':
    main()
