"""``make demo``: the main job on the embedded default, with no hardware.

1. ``gx3_sim`` (a simulated 3DM-GX3-25 with the thesis's noise model) on a pseudo-terminal ->
   the ``driver`` node -> the ``allan`` and ``denoise`` nodes, over real DDS, for about a minute
   (``DEMO_SECONDS``), with the noise coefficients printed as they arrive;
2. ``analyze`` on a longer simulated recording (2 h at 100 Hz, written as an MCAP rosbag2),
   writing its report and plots to a folder named at the end.

Parts that are missing are skipped with a note, so the demo runs whatever exists.
"""

import math
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import time

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / 'demo_out'
SECONDS = float(os.environ.get('DEMO_SECONDS', '60'))
TERMS = ('quantization', 'white_noise', 'bias_instability', 'rate_random_walk', 'rate_ramp')
AXES = ('gyro_x', 'gyro_y', 'gyro_z', 'accel_x', 'accel_y', 'accel_z')


def executable(name):
    """The built executable, looked up like ``ros2 run imu_allan NAME``."""
    from ament_index_python.packages import get_package_prefix
    path = Path(get_package_prefix('imu_allan')) / 'lib' / 'imu_allan' / name
    return str(path) if path.is_file() and os.access(path, os.X_OK) else None


def stop(procs):
    """SIGINT every process (nodes stop cleanly), then kill what is left."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + 5.0
    for proc in procs:
        try:
            proc.wait(timeout=max(deadline - time.monotonic(), 0.1))
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def live_part(env):
    """Simulator -> driver -> allan + denoise, coefficients printed as they arrive."""
    names = ('gx3_sim', 'driver', 'allan', 'denoise')
    exes = {n: executable(n) for n in names}
    missing = [n for n, path in exes.items() if path is None]
    if missing:
        print(f'demo: live part skipped, not built yet: {", ".join(missing)}')
        return
    procs = []
    try:
        sim = subprocess.Popen([exes['gx3_sim'], '--seed', '1'], stdout=subprocess.PIPE,
                               text=True, env=env)
        procs.append(sim)
        port = sim.stdout.readline().strip()
        print(f'demo: simulated 3DM-GX3-25 on {port}')
        procs.append(subprocess.Popen([exes['driver'], '--ros-args', '-p', f'port:={port}',
                                       '-p', 'rate_hz:=100.0', '--log-level', 'warn'], env=env))
        procs.append(subprocess.Popen([exes['allan'], '--ros-args', '-p', 'rate_hz:=100.0',
                                       '-p', 'publish_period:=5.0', '--log-level', 'warn'],
                                      env=env))
        procs.append(subprocess.Popen([exes['denoise'], '--ros-args', '--log-level', 'warn'],
                                      env=env))
        watch(SECONDS)
    finally:
        stop(procs)


def watch(seconds):
    """Subscribe to the live topics and print a table each time coefficients arrive."""
    import rclpy
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray

    rclpy.init()
    node = rclpy.create_node('imu_allan_demo')
    counts = {'raw': 0, 'denoised': 0, 'coeffs': 0}
    latest = {}

    def on_coeffs(msg):
        counts['coeffs'] += 1
        latest['data'] = list(msg.data)

    node.create_subscription(Imu, 'imu/data_raw',
                             lambda _m: counts.__setitem__('raw', counts['raw'] + 1),
                             qos_profile_sensor_data)
    node.create_subscription(Imu, 'imu/data_denoised',
                             lambda _m: counts.__setitem__('denoised', counts['denoised'] + 1),
                             qos_profile_sensor_data)
    node.create_subscription(Float64MultiArray, 'imu/allan_coeffs', on_coeffs, 10)
    start = time.monotonic()
    shown = 0
    tty = sys.stdout.isatty()
    last_line = -5.0
    try:
        while time.monotonic() - start < seconds:
            rclpy.spin_once(node, timeout_sec=0.2)
            elapsed = time.monotonic() - start
            if tty or elapsed - last_line >= 5.0:  # a live bar on a terminal, a line per 5 s
                last_line = elapsed
                bar = '#' * int(30 * elapsed / seconds)
                sys.stdout.write(f'{chr(13) if tty else ""}[{bar:30}] {elapsed:5.1f}/'
                                 f'{seconds:.0f} s  imu/data_raw {counts["raw"]:6d}  '
                                 f'imu/data_denoised {counts["denoised"]:6d}  '
                                 f'imu/allan_coeffs {counts["coeffs"]:3d}' + ('' if tty else '\n'))
                sys.stdout.flush()
            if counts['coeffs'] > shown and 'data' in latest:
                shown = counts['coeffs']
                print('\n' + table(latest['data']))
    finally:
        print()
        node.destroy_node()
        rclpy.try_shutdown()


def table(data):
    """imu/allan_coeffs (axis x term x stat) as text: conventional units, 68.3 % intervals."""
    def get(a, t, s):
        return data[(a * len(TERMS) + t) * 3 + s]

    def fmt(a, t, scale):
        value, low, high = (get(a, t, s) * scale for s in range(3))
        if math.isnan(value):
            return f'{"not yet (needs longer data)":>30}'
        return f'{value:9.4g} [{low:8.4g}, {high:8.4g}]'.rjust(30)

    lines = ['noise coefficients from imu/allan_coeffs (continuous-time, 68.3 % intervals):',
             f'{"axis":8} {"white noise N":>30} {"":11} {"bias instability B":>30}']
    for a, axis in enumerate(AXES):
        gyro = axis.startswith('gyro')
        n_scale = 60.0 * 180.0 / math.pi if gyro else 60.0  # SI -> deg/sqrt(h), m/s/sqrt(h)
        b_scale = 3600.0 * 180.0 / math.pi if gyro else 3600.0  # SI -> deg/h, m/s/h
        n_unit, b_unit = ('deg/sqrt(h)', 'deg/h') if gyro else ('m/s/sqrt(h)', 'm/s/h')
        lines.append(f'{axis:8} {fmt(a, 1, n_scale)} {n_unit:11} {fmt(a, 2, b_scale)} {b_unit}')
    return '\n'.join(lines)


def offline_part(env):
    """Simulate 2 h of the thesis model, write an MCAP bag, run analyze on it."""
    import numpy as np

    from imu_allan import simulate, thesis_gx3_25_model
    from imu_allan.formats.bag_writer import write_imu_bag
    from imu_allan.formats.samples import Samples

    analyze = executable('analyze')
    if analyze is None:
        print('demo: offline part skipped, analyze not built')
        return
    bag = OUT / 'recording_2h'
    report = OUT / 'report'
    shutil.rmtree(bag, ignore_errors=True)
    shutil.rmtree(report, ignore_errors=True)
    n = 100 * 7200
    print(f'demo: simulating 2 h at 100 Hz of the thesis 3DM-GX3-25 model -> {bag}')
    data = simulate(thesis_gx3_25_model(), n, 100.0, seed=7)
    data[:, 5] -= 9.80665  # the simulator's gravity on -z, as gx3_sim does by default
    write_imu_bag(bag, Samples(t=1.7e9 + np.arange(n) / 100.0, data=data), storage='mcap')
    print(f'demo: analyze {bag} --out {report}')
    subprocess.run([analyze, str(bag), '--out', str(report)], env=env, check=False)
    print(f'demo: report and plots written to {report}')


def main():
    """Run both parts."""
    # this process subscribes too, so it needs the same domain as the nodes it starts
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(120, 200)))
    env = dict(os.environ)
    OUT.mkdir(exist_ok=True)
    live_part(env)
    offline_part(env)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
