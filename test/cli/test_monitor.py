"""
The built ``monitor`` command over real DDS: JSON snapshot, terminal redraw, timeout.

* ``--once --json`` against the built allan node fed 60 s of simulated data
  (``nodes/allan_feed.py``) returns exactly the coefficients a direct subscriber decodes;
* on a real pseudo-terminal the table is redrawn in place (cursor-home + clear-to-end) and shows
  two different estimates that this process publishes in turn; with stdout a pipe the same run
  prints plain lines (no escape sequences);
* ``--once --timeout 1`` with nothing running exits 1 with one line on stderr naming the topic
  as resolved with ``--namespace`` or a ``--ros-args`` remapping; a bad argument exits 2;
* without ROS: the recording advice is the node's own sentences per axis (the key-values come
  back with ``--verbose``), and a term not resolved shows its upper limit.

About 60 s in all on the 2-core test machine (node and monitor start-up dominate).
"""

import json
import math
import os
import select
import signal
import subprocess
import threading
import time
from types import SimpleNamespace

from conftest import DOMAIN, executable, ros_env, run_command
from imu_allan.cli.monitor import format_interval, MonitorState, REDRAW, render
from imu_allan.core.fit.advisor import Advice, Limit, TermAdvice, Unresolved
from imu_allan.core.units import AXES, conventional, IEEE_TERMS
from imu_allan.nodes.allan import multiarray
from imu_allan.report.advice import advice_statuses
from imu_allan.report.coeffs_layout import COEFF_LABELS, decode_coefficients
from nodes.allan_feed import AllanFeed
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')


@pytest.mark.ros
def test_once_json_equals_a_direct_subscriber(ros_context):
    """The snapshot's SI values and intervals are the node's numbers, bit for bit."""
    from std_msgs.msg import Float64MultiArray

    with AllanFeed(ros_context, DOMAIN) as feed:
        coeffs = []
        feed.node.create_subscription(Float64MultiArray, 'imu/allan_coeffs',
                                      lambda m: coeffs.append((time.monotonic(), m)), 10)
        done = feed.feed()
        assert feed.spin_until(lambda: coeffs and coeffs[-1][0] > done, 20)
        direct = decode_coefficients(coeffs[-1][1])
        proc = run_command('monitor', '--once', '--json', '--timeout', 30,
                           env=ros_env(DOMAIN), timeout=60)
    assert proc.returncode == 0, proc.stderr
    snap = json.loads(proc.stdout)
    assert snap['topics']['coeffs'] == '/imu/allan_coeffs'
    detected = 0
    for i, axis in enumerate(AXES):
        for j, term in enumerate(IEEE_TERMS):
            value, low, high = direct[i, j]
            entry = snap['axes'][axis].get(term)
            if math.isnan(value):
                assert entry is None, (axis, term)
                continue
            detected += 1
            assert entry['value'] == value and entry['ci'] == [low, high], (axis, term)
            conv, unit = conventional(axis, term, value)
            assert entry['conventional']['value'] == conv
            assert entry['conventional']['unit'] == unit
    assert detected >= 6  # white noise on every axis at least
    stream = snap['status']['allan: IMU stream']
    assert stream['values']['samples_total'] == str(feed.n)


def _table(scale):
    """Return a coefficient table: white noise and bias instability on every axis, x ``scale``."""
    table = np.full((len(AXES), len(IEEE_TERMS), 3), np.nan)
    for k, term in ((1, 'white_noise'), (2, 'bias_instability')):
        base = (1e-4 if term == 'white_noise' else 2e-5) * scale
        table[:, k] = [base, 0.9 * base, 1.1 * base]
    return table


def _read_until(fd, text, timeout, seen):
    """Read a pty master into ``seen`` (a list of str) until ``text`` appears."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        ready, _, _ = select.select([fd], [], [], 0.1)
        if ready:
            try:
                seen.append(os.read(fd, 65536).decode(errors='replace'))
            except OSError:  # the child closed the terminal
                break
        if text in ''.join(seen):
            return True
    return False


def _threads(pid):
    """Return what each thread of a process waits in (kernel wait channel), for a message."""
    out = {}
    for tid in os.listdir(f'/proc/{pid}/task'):
        with open(f'/proc/{pid}/task/{tid}/comm') as comm, \
                open(f'/proc/{pid}/task/{tid}/wchan') as wchan:
            out[f'{tid} {comm.read().strip()}'] = wchan.read()
    return out


@pytest.mark.ros
def test_terminal_redraws_in_place_and_pipe_gets_plain_lines(ros_context, tmp_path):
    """Two estimates in turn: redrawn in place on a pty; plain lines on a pipe; Ctrl-C exits 0."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from std_msgs.msg import Float64MultiArray

    node = rclpy.create_node('fake_allan', context=ros_context)
    pub = node.create_publisher(Float64MultiArray, 'imu/allan_coeffs', 10)
    diag = node.create_publisher(DiagnosticArray, '/diagnostics', 10)
    master, slave = os.openpty()
    cmd = [executable('monitor'), '--duration', '60']
    errors = [open(tmp_path / f'stderr_{k}.txt', 'w+') for k in range(2)]
    on_tty = subprocess.Popen(cmd, stdout=slave, stderr=errors[0], env=ros_env(DOMAIN))
    on_pipe = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=errors[1], text=True,
                               env=ros_env(DOMAIN))
    os.close(slave)
    plain_parts = []  # drained all along, so the monitor never blocks on a full pipe
    reader = threading.Thread(target=lambda: plain_parts.extend(iter(on_pipe.stdout.readline,
                                                                     '')), daemon=True)
    reader.start()
    seen, texts = [], []
    try:
        for scale in (1.0, 3.0):
            table = _table(scale)
            text = format_interval('gyro_x', 'white_noise', table[0, 1])
            texts.append(text)
            array = DiagnosticArray()
            array.status.append(DiagnosticStatus(
                name='allan: recording advice', level=b'\x01',
                message=f'record about {scale:g} h more',
                values=[KeyValue(key='gyro_x.bias_instability_more_s', value='5400')]))
            deadline = time.monotonic() + 30
            while time.monotonic() < deadline:
                pub.publish(multiarray(table, COEFF_LABELS))
                diag.publish(array)
                if (_read_until(master, text, 0.5, seen)
                        and f'{scale:g} h more' in ''.join(seen)
                        and text in ''.join(plain_parts)):
                    break
            else:
                pytest.fail(f'never shown: {text!r}; pty: {"".join(seen)[-1500:]}; pipe: '
                            f'{"".join(plain_parts)[-1500:]}')
        for proc in (on_tty, on_pipe):
            proc.send_signal(signal.SIGINT)
        # keep reading the terminal: a monitor blocked writing to a full pty cannot exit.  The
        # bound is generous: on the shared test machine a starved process needs seconds to
        # close its DDS participant.
        end = time.monotonic() + 60
        while time.monotonic() < end and None in (on_tty.poll(), on_pipe.poll()):
            _read_until(master, '\x00', 0.2, seen)
            time.sleep(0.05)
        codes = [on_tty.poll(), on_pipe.poll()]
        hung = {p.pid: _threads(p.pid) for p in (on_tty, on_pipe) if p.poll() is None}
        reader.join(timeout=5)
    finally:
        for proc in (on_tty, on_pipe):
            if proc.poll() is None:
                proc.kill()
            proc.wait()
        os.close(master)
        node.destroy_node()
    stderr = [e.seek(0) or e.read() for e in errors]
    for e in errors:
        e.close()
    assert codes == [0, 0], (stderr, hung)
    plain = ''.join(plain_parts)
    screen = ''.join(seen)
    assert screen.count(REDRAW) >= 2
    assert texts[0] != texts[1] and texts[0] in screen and texts[1] in screen
    # the second estimate is drawn after a redraw that follows the first one
    assert screen.rfind(REDRAW) > screen.find(texts[0])
    assert 'advice   WARN  record about 3 h more' in screen
    assert '\x1b' not in plain and texts[0] in plain and texts[1] in plain


@pytest.mark.ros
@pytest.mark.parametrize('args, topic', [
    ((), '/imu/allan_coeffs'),
    (('--namespace', 'robot1'), '/robot1/imu/allan_coeffs'),
    (('--ros-args', '-r', 'imu/allan_coeffs:=/elsewhere/coeffs'), '/elsewhere/coeffs'),
])
def test_once_times_out_with_one_line(args, topic):
    """Nothing running on this domain: exit 1, one line naming the (resolved) topic."""
    # a domain no test uses (conftest: 100-199; make demo: 120-200), so nothing answers
    proc = run_command('monitor', '--once', '--timeout', 1, *args,
                       env=ros_env(201 + DOMAIN % 30), timeout=60)
    assert proc.returncode == 1
    assert proc.stdout == ''
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f' {topic} ' in lines[0], proc.stderr


@pytest.mark.ros
def test_bad_argument_one_line_exit_2():
    proc = run_command('monitor', '--once', '--timeout', '0', timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.count('\n') == 1 and '--timeout' in proc.stderr


def _advice_statuses():
    """
    Return the allan node's advice statuses as /diagnostics carries them (rendered in report/).

    White noise met on gyro_x, bias instability 700 s short there; on gyro_y the open sets
    {N, B} and {N, GM} that 3158 s more tells apart; a rate ramp that no open set holds.
    """
    advice = Advice(targets={'white_noise': 0.02, 'bias_instability': 0.05}, duration_s=600.0)
    advice.axes = {'gyro_x': {'white_noise': TermAdvice(0.003, 0.0),
                              'bias_instability': TermAdvice(0.15, 700.0)},
                   'gyro_y': {'white_noise': TermAdvice(0.003, 0.0)}}
    advice.unresolved = [Unresolved('gyro_y', ('gauss_markov', 'bias_instability'), 3158.0,
                                    sets=(('white_noise', 'bias_instability'),
                                          ('white_noise', 'gauss_markov')))]
    advice.limits = {'gyro_x': {'rate_ramp': Limit(1e-6, 120.0)}}
    out = []
    for status in advice_statuses(advice, 'allan: recording advice', 'allan: '):
        values = [SimpleNamespace(key=k, value=f'{v:.6g}' if isinstance(v, float) else str(v))
                  for k, v in status.values.items()]
        out.append(SimpleNamespace(name=status.name, level=bytes([status.level]),
                                   message=status.message, values=values))
    return out


def test_render_shows_the_nodes_advice_sentences_and_verbose_keeps_key_values():
    """The advice block is the node's sentences, per axis, as sent; --verbose adds key=value."""
    state = MonitorState()
    statuses = _advice_statuses()
    state.on_diagnostics(SimpleNamespace(status=statuses))
    topics = {'coeffs': '/imu/allan_coeffs'}
    plain = '\n'.join(render(state, topics, width=400))
    assert f'advice   WARN  {statuses[0].message}' in plain
    for status in statuses[1:]:
        axis = status.name.removeprefix('allan: ').removesuffix(' advice')
        assert f'{axis}: {status.message}' in plain
    assert 'cannot tell yet Gauss-Markov or bias instability' in plain
    assert '.more_s=' not in plain and 'nan' not in plain
    verbose = render(state, topics, verbose=True)
    assert 'record_more_s=3158' in '\n'.join(verbose)
    assert all(len(line) <= 99 for line in verbose)


def test_unresolved_terms_show_their_upper_limit():
    """A term not resolved is '< limit' in the table, from the coefficients' limit block."""
    table = _table(1.0)
    table[0, IEEE_TERMS.index('bias_instability')] = np.nan
    limits = np.full((len(AXES), len(IEEE_TERMS)), np.nan)
    limits[0, IEEE_TERMS.index('bias_instability')] = 1e-4
    msg = multiarray(table, COEFF_LABELS)
    msg.data.extend([0.5] * len(AXES) + limits.ravel().tolist())
    state = MonitorState()
    state.on_coeffs(msg)
    text = '\n'.join(render(state, {'coeffs': '/imu/allan_coeffs'}))
    assert f'< {conventional("gyro_x", "bias_instability", 1e-4)[0]:.3g} deg/h' in text
    assert state.snapshot()['upper_limits']['gyro_x'] == {'bias_instability': 1e-4}
