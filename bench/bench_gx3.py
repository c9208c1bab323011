"""
Benchmark of the 3DM-GX3-25 path: parser throughput and the live driver at 1000 Hz.

1. ``StreamParser`` + ``decode_records`` on a synthetic stream (with junk), packets/s.
2. ``gx3_sim`` (921600 baud, 1000 Hz, ``--record-truth``) -> built ``driver`` for
   ``--seconds`` (default 30): the driver PROCESS's CPU share of one core (user + system time
   of all its threads from /proc/<pid>/stat over the measured window, so DDS threads count
   too) and the machine's load average.  A raw subscriber in this process receives
   imu/data_raw; every message received in the window is matched (by its float32 gyro
   values) to the simulator's truth log, so the count of records SENT between the first and
   the last received one is known exactly: nothing dropped means every one of them arrived,
   in order.  Losses are split by cause (not read from the pty in time, lost on the way from
   the driver to the subscriber).  Goal (issue 14): < 8 % of one core, nothing dropped.

Run through ``make bench`` (needs the colcon-built package on AMENT_PREFIX_PATH);
``BENCH_DRIVER_ARGS`` adds driver arguments (e.g. "-p read_period:=0.01").
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


def read_truth(path):
    """Return the simulator's data records as (status list, (n, 3) float gyro rad/s)."""
    status, gyro = [], []
    with open(path, encoding='utf-8') as stream:
        for line in stream:
            cols = line.rstrip('\n').split(',')
            if line.startswith('#') or cols[0] == 'index' or cols[2] != '0xC2':
                continue
            if cols[1] in ('reply', 'garbage', 'event'):
                continue
            status.append(cols[1])
            gyro.append([float(v) for v in cols[7:10]])
    return status, np.array(gyro, dtype=np.float64).reshape(-1, 3)


def account(blobs, truth_path):
    """
    Match received messages to the records sent; return a dict of counts.

    ``blobs``: serialized Imu messages in arrival order.  ``sent`` counts the simulator's
    records from the first to the last one received (whatever happened to them), ``received``
    those that arrived, ``lost`` the rest by truth status ('ok': written to the pty and then
    lost by the driver or DDS; 'unread': the pty was full because the driver read too late;
    others: the simulator's own), ``out_of_order`` arrivals of an earlier record after a
    later one.
    """
    from imu_allan.formats.imu_cdr import decode_rows
    status, gyro = read_truth(truth_path)
    if not blobs:
        return {'sent': 0, 'received': 0, 'lost': {}, 'out_of_order': 0, 'unmatched': 0}
    size = len(blobs[0])
    rows = np.frombuffer(b''.join(blobs), dtype=np.uint8).reshape(len(blobs), size)
    ok, _, data = decode_rows(rows, ros1=False)
    index = {tuple(g): i for i, g in enumerate(gyro.tolist())}
    got = [index.get(tuple(g)) for g in data[ok, :3].tolist()]
    unmatched = got.count(None) + int((~ok).sum())
    got = np.array([i for i in got if i is not None], dtype=np.int64)
    if not got.size:
        return {'sent': 0, 'received': 0, 'lost': {}, 'out_of_order': 0, 'unmatched': unmatched}
    first, last = int(got.min()), int(got.max())
    arrived = np.zeros(last - first + 1, dtype=bool)
    arrived[got - first] = True
    lost = {}
    for i in np.flatnonzero(~arrived):
        lost[status[first + i]] = lost.get(status[first + i], 0) + 1
    return {'sent': last - first + 1, 'received': int(arrived.sum()), 'lost': lost,
            'out_of_order': int(np.sum(np.diff(got) <= 0)), 'unmatched': unmatched}


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
    truth = os.path.join(tmp, 'truth.csv')
    sim = subprocess.Popen([os.path.join(lib, 'gx3_sim'), '--baud', '921600', '--seed', '1',
                            '--link', link, '--record-truth', truth],
                           stdout=subprocess.PIPE, env=env)
    sim.stdout.readline()
    driver = subprocess.Popen([os.path.join(lib, 'driver'), '--ros-args', '-p',
                               f'port:={link}', '-p', 'baud:=921600', '-p',
                               f'rate_hz:={rate_hz}'] + EXTRA, env=env, stderr=subprocess.DEVNULL)
    rclpy.init()
    node = rclpy.create_node('bench_gx3')
    window = []         # serialized messages received inside the measured window
    measuring = [False]
    total = [0]
    diags = []
    qos = QoSProfile(depth=1000, reliability=qos_profile_sensor_data.reliability)

    def on_imu(blob):
        total[0] += 1
        if measuring[0]:
            window.append(blob)

    node.create_subscription(Imu, 'imu/data_raw', on_imu, qos, raw=True)
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
        measuring[0] = True
        c0, t0 = cpu_seconds(driver.pid), time.monotonic()
        spin(seconds)
        c1, t1 = cpu_seconds(driver.pid), time.monotonic()
        measuring[0] = False
        load = os.getloadavg()
        spin(1.2)
        last = diag()
    finally:
        driver.send_signal(signal.SIGINT)
        driver.wait(10)
        sim.send_signal(signal.SIGTERM)
        sim.wait(10)
        node.destroy_node()
        rclpy.try_shutdown()
    res = account(window, truth)
    res.update({
        'seconds': t1 - t0, 'cpu_share': (c1 - c0) / (t1 - t0), 'load': load,
        'records': int(last.get('packets', 0)) - int(first.get('packets', 0)),
        'dropped_packets': int(last.get('dropped_packets', -1)),
        'checksum_failures': int(last.get('checksum_failures', -1)),
        'rate_achieved_hz': last.get('rate_achieved_hz'), 'received_total': total[0],
    })
    return res


def main():
    """Print the benchmark results."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=30.0)
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
    lost = sum(res['lost'].values())
    causes = ', '.join(f'{n} {k}' for k, n in sorted(res['lost'].items())) or 'none'
    print(f'gx3 driver at {args.rate_hz:g} Hz, 921600 baud, {res["seconds"]:.1f} s: '
          f'CPU {100 * res["cpu_share"]:.1f} % of one core (driver process, all threads), '
          f'load average {res["load"][0]:.1f} / {res["load"][1]:.1f} (1 / 5 min)')
    print(f'  messages: {res["sent"]} sent by the simulator from the first to the last one '
          f'received in the window, {res["received"]} received, lost {lost} ({causes}), '
          f'{res["out_of_order"]} out of order, {res["unmatched"]} unmatched; driver '
          f'diagnostics: {res["records"]} records, {res["dropped_packets"]} dropped, '
          f'{res["checksum_failures"]} checksum failures, achieved {res["rate_achieved_hz"]} Hz')
    nothing_dropped = (lost == 0 and res['out_of_order'] == 0 and res['unmatched'] == 0
                       and res['dropped_packets'] == 0
                       and res['sent'] >= 0.99 * args.rate_hz * res['seconds'])
    goal(f'driver at {args.rate_hz:g} Hz: {100 * res["cpu_share"]:.1f} % of one core, '
         f'{lost} of {res["sent"]} messages dropped ({causes}) over {res["seconds"]:.0f} s '
         f'(< 8 % of one core, nothing dropped)', nothing_dropped and res['cpu_share'] < 0.08)
    return 0


if __name__ == '__main__':
    sys.exit(main())
