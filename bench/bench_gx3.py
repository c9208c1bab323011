"""
Benchmark of the 3DM-GX3-25 path: parser throughput and the live driver at 1000 Hz.

1. ``StreamParser`` + ``decode_records`` on a synthetic stream (with junk), packets/s.
2. ``gx3_sim`` (921600 baud, 1000 Hz) -> built ``driver`` for ``--seconds`` (default 60):
   the driver's CPU share of one core (from /proc/<pid>/stat over the measured window), the
   records published, and the dropped-packet / checksum counters from its /diagnostics
   (goal: 0 dropped, < 8 % of one core).  A subscriber in this process receives the
   messages, so DDS really delivers them.

Run through ``make bench`` (needs the colcon-built package on AMENT_PREFIX_PATH).
"""

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time

from benchlib import goal, header
from imu_allan.device import gx3_protocol as p
from imu_allan.device.gx3_stream import StreamParser
import numpy as np

#: Extra driver arguments (e.g. "-p read_period:=0.01") for experiments.
EXTRA = os.environ.get('BENCH_DRIVER_ARGS', '').split()


def bench_parser(n=100_000):
    """Frame and decode ``n`` 0xC2 records fed in 4 KiB chunks; return packets/s."""
    rng = np.random.default_rng(0)
    values = rng.normal(size=(n, 6)).astype(np.float32)
    parts = []
    for k in range(n):
        parts.append(p.encode_record(0xC2, values[k].tolist(), 62 * k))
        if k % 1000 == 999:
            parts.append(b'\x00\x01\x02')    # a little junk now and then
    data = b''.join(parts)
    parser = StreamParser()
    t0 = time.perf_counter()
    packets = []
    for i in range(0, len(data), 4096):
        packets += parser.feed(data[i:i + 4096])
    rec = p.decode_records(0xC2, packets)
    dt = time.perf_counter() - t0
    assert len(packets) == n and np.array_equal(rec['gyro'], values[:, 3:])
    return n / dt, len(data) / dt


def cpu_seconds(pid):
    """User + system CPU seconds of a process."""
    with open(f'/proc/{pid}/stat') as stream:
        fields = stream.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def bench_live(seconds, rate_hz):
    """Run sim + driver; return a dict of results."""
    from ament_index_python.packages import get_package_prefix
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.qos import qos_profile_sensor_data, QoSProfile
    from sensor_msgs.msg import Imu
    lib = os.path.join(get_package_prefix('imu_allan'), 'lib', 'imu_allan')
    env = dict(os.environ, ROS_DOMAIN_ID=str(os.getpid() % 100 + 100))
    os.environ['ROS_DOMAIN_ID'] = env['ROS_DOMAIN_ID']
    tmp = tempfile.mkdtemp(prefix='bench_gx3_')
    link = os.path.join(tmp, 'gx3')
    sim = subprocess.Popen([os.path.join(lib, 'gx3_sim'), '--baud', '921600', '--seed', '1',
                            '--link', link], stdout=subprocess.PIPE, env=env)
    sim.stdout.readline()
    driver = subprocess.Popen([os.path.join(lib, 'driver'), '--ros-args', '-p',
                               f'port:={link}', '-p', 'baud:=921600', '-p',
                               f'rate_hz:={rate_hz}'] + EXTRA, env=env, stderr=subprocess.DEVNULL)
    rclpy.init()
    node = rclpy.create_node('bench_gx3')
    count = [0]
    diags = []
    qos = QoSProfile(depth=1000, reliability=qos_profile_sensor_data.reliability)
    node.create_subscription(Imu, 'imu/data_raw', lambda m: count.__setitem__(0, count[0] + 1),
                             qos)
    node.create_subscription(DiagnosticArray, '/diagnostics', diags.append, 10)

    def spin(duration):
        end = time.monotonic() + duration
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.01)

    def diag():
        return {kv.key: kv.value for kv in diags[-1].status[0].values} if diags else {}

    try:
        end = time.monotonic() + 30
        while time.monotonic() < end and int(diag().get('packets', 0)) < rate_hz * 2:
            spin(0.2)
        first = diag()
        c0, t0 = cpu_seconds(driver.pid), time.monotonic()
        spin(seconds)
        c1, t1 = cpu_seconds(driver.pid), time.monotonic()
        spin(1.2)
        last = diag()
    finally:
        driver.send_signal(signal.SIGINT)
        driver.wait(10)
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)
        node.destroy_node()
        rclpy.try_shutdown()
    return {
        'seconds': t1 - t0, 'cpu_share': (c1 - c0) / (t1 - t0),
        'records': int(last.get('packets', 0)) - int(first.get('packets', 0)),
        'dropped': int(last.get('dropped_packets', -1)),
        'checksum_failures': int(last.get('checksum_failures', -1)),
        'rate_achieved_hz': last.get('rate_achieved_hz'), 'received': count[0],
    }


def main():
    """Print the benchmark results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=60.0)
    ap.add_argument('--rate-hz', type=float, default=1000.0)
    ap.add_argument('--parser-only', action='store_true')
    args = ap.parse_args()
    header('bench_gx3')
    pps, bps = bench_parser()
    print(f'gx3 parser: {pps:,.0f} records/s ({bps / 1e6:.1f} MB/s) framing + decoding '
          f'31-byte 0xC2 records in 4 KiB chunks')
    if args.parser_only:
        return 0
    res = bench_live(args.seconds, args.rate_hz)
    print(f'gx3 driver at {args.rate_hz:g} Hz, 921600 baud, {res["seconds"]:.1f} s: '
          f'CPU {100 * res["cpu_share"]:.1f} % of one core, {res["records"]} records, '
          f'{res["dropped"]} dropped, {res["checksum_failures"]} checksum failures, '
          f'achieved {res["rate_achieved_hz"]} Hz, {res["received"]} received by a subscriber')
    ok = res['dropped'] == 0 and res['records'] >= 0.99 * args.rate_hz * res['seconds']
    goal(f'gx3 driver at {args.rate_hz:g} Hz: {100 * res["cpu_share"]:.1f} % of one core, '
         f'{res["dropped"]} dropped (goal < 8 %, 0 dropped)', ok and res['cpu_share'] < 0.08)
    return 0


if __name__ == '__main__':
    sys.exit(main())
