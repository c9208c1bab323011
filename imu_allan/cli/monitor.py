"""
monitor: the live view of a running allan node, for an operator standing next to the robot.

Subscribes ``imu/allan_coeffs``, ``imu/allan_deviation`` (relative names: ``--namespace`` or
ROS remapping after ``--ros-args`` move them) and ``/diagnostics``, and shows per axis the
resolved terms with their 68.3 % intervals in conventional units (or the 95 % upper limit of a
term not resolved yet), the stream health and the node's recording advice; docs/online.md
(section monitor) shows the table and the options.  Diagnostic statuses are read generically:
every status named ``<node>: ...`` (``--node``, default ``allan``) is shown;
``<node>: IMU stream`` and ``<node>: recording advice`` get their own lines.
"""

import math
import os
import shutil
import signal
import sys
import textwrap
import threading
import time

from .common import ArgumentParser, guarded
from ..core.fit.adequacy import ADEQUACY_LEVEL
from ..core.live.health import LEVEL_NAMES
from ..core.units import AXES, conventional, IEEE_TERMS
from ..errors import InputError
from ..report import strict_json
from ..report.coeffs_layout import (
    coefficient_terms,
    decode_adequacy,
    decode_coefficients,
    decode_deviation,
    decode_limits,
)

#: Terminal control: cursor home, then clear to the end of the screen (redraw in place).
REDRAW = '\x1b[H\x1b[J'
#: Seconds to wait, after coefficients arrive with ``--once``, for the same cycle's diagnostics.
DIAGNOSTICS_GRACE_S = 1.5
TOPICS = ('imu/allan_coeffs', 'imu/allan_deviation', '/diagnostics')


def build_parser():
    """Return the command line (ROS arguments after ``--ros-args`` are passed to rclpy)."""
    p = ArgumentParser(
        prog='monitor',
        description='Live view of a running allan node: per-axis noise coefficients with '
                    '68.3 % intervals in conventional units, the IMU stream health and the '
                    'recording advice, from imu/allan_coeffs, imu/allan_deviation and '
                    '/diagnostics.  ROS arguments (remapping, domain) go after --ros-args.')
    p.add_argument('--namespace', default='', metavar='NS',
                   help='namespace of the allan node (its topics are NS/imu/...)')
    p.add_argument('--node', default='allan', metavar='NAME',
                   help='name of the allan node, whose /diagnostics statuses are shown '
                        '(default: allan)')
    p.add_argument('--once', action='store_true',
                   help='print one snapshot once coefficients arrive, then exit')
    p.add_argument('--json', action='store_true', help='print the decoded snapshot as JSON')
    p.add_argument('--verbose', '-v', action='store_true',
                   help='also print the raw key=value lists of the stream and advice statuses')
    p.add_argument('--timeout', type=float, default=30.0, metavar='S',
                   help='with --once: exit 1 if no coefficients arrive within S seconds '
                        '(default 30)')
    p.add_argument('--duration', type=float, default=0.0, metavar='S',
                   help='stop after S seconds (default: until Ctrl-C)')
    return p


def split_ros_args(argv):
    """``(own arguments, full argument list for rclpy)``: ours stop at ``--ros-args``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    return own, argv


def _level(status):
    """Integer level of a DiagnosticStatus (rclpy gives a bytes of length 1)."""
    level = status.level
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


class MonitorState:
    """The latest messages of one allan node, decoded; ROS-free (callbacks take messages)."""

    def __init__(self, node_name='allan'):
        """Start empty; statuses named ``<node_name>: ...`` are kept."""
        self.prefix = f'{node_name}: '
        self.coeffs = None
        self.adequacy = None  # each axis's adequacy p, from the coefficients' trailing block
        self.limits = None  # (axis, term) 95 % upper limits of the terms not resolved
        self.deviation = None
        self.statuses = {}
        self.received = {'coeffs': 0, 'deviation': 0, 'diagnostics': 0}
        self.arrived = {}
        self.version = 0

    def on_coeffs(self, msg):
        """``imu/allan_coeffs`` callback; a bad layout becomes an ERROR line, not a crash."""
        self._store('coeffs', decode_coefficients, msg)
        try:  # None from a publisher without these blocks
            self.adequacy, self.limits = decode_adequacy(msg), decode_limits(msg)
        except InputError:
            self.adequacy = self.limits = None

    def on_deviation(self, msg):
        """``imu/allan_deviation`` callback."""
        self._store('deviation', decode_deviation, msg)

    def _store(self, key, decode, msg):
        try:
            value = decode(msg)
        except InputError as exc:
            self.statuses[f'{self.prefix}monitor'] = {
                'level': 'ERROR', 'message': str(exc), 'values': {}}
            return
        setattr(self, key, value)
        self.received[key] += 1
        self.arrived[key] = time.monotonic()
        self.version += 1

    def on_diagnostics(self, msg):
        """``/diagnostics`` callback: keep this node's statuses (the newest of each name)."""
        mine = [s for s in msg.status if s.name.startswith(self.prefix)]
        if not mine:
            return
        for status in mine:
            self.statuses[status.name] = {
                'level': LEVEL_NAMES.get(_level(status), str(_level(status))),
                'message': status.message,
                'values': {kv.key: kv.value for kv in status.values}}
        self.received['diagnostics'] += 1
        self.arrived['diagnostics'] = time.monotonic()
        self.version += 1

    def status(self, suffix):
        """Return the kept status ``<node>: <suffix>`` or None."""
        return self.statuses.get(self.prefix + suffix)

    def snapshot(self, topics=None):
        """Return everything known as a dictionary (SI and conventional units; NaN: unknown)."""
        now = time.monotonic()
        out = {'node': self.prefix[:-2], 'topics': dict(topics or {}),
               'received': dict(self.received),
               'age_s': {k: (now - t) for k, t in self.arrived.items()},
               'units': 'SI with conventional beside; noise coefficients are continuous-time, '
                        '68.3 % intervals',
               'axes': {} if self.coeffs is None else coefficient_terms(self.coeffs),
               'deviation': None, 'status': dict(self.statuses),
               'adequacy_p': (None if self.adequacy is None else
                              dict(zip(AXES, self.adequacy.tolist()))),
               'upper_limits': (None if self.limits is None else
                                {a: {t: v for t, v in zip(IEEE_TERMS, row) if math.isfinite(v)}
                                 for a, row in zip(AXES, self.limits.tolist())})}
        if self.deviation is not None:
            tau, adev = self.deviation
            out['deviation'] = {'tau': tau.tolist(), 'adev': dict(zip(AXES, adev.T.tolist()))}
        return out


def format_interval(axis, term, stats):
    """
    ``value [low, high] unit`` in conventional units, or ``-`` when not detected.

    Enough significant digits that the interval's ends differ from the value (3 to 6).
    """
    value, low, high = stats
    if not math.isfinite(value):
        return '-'
    v, unit = conventional(axis, term, value)
    lo, hi = conventional(axis, term, low)[0], conventional(axis, term, high)[0]
    spread = min(abs(v - lo), abs(hi - v)) / abs(v) if v else 1.0
    digits = min(6, max(3, 2 + math.ceil(-math.log10(spread)))) if spread > 0 else 6
    return f'{v:.{digits}g} [{lo:.{digits}g}, {hi:.{digits}g}] {unit}'


def _status_line(label, status, width=None):
    """``label  LEVEL  message`` of a kept status (wrapped to ``width`` columns if given)."""
    if status is None:
        return [f'{label:9}(none yet)']
    line = f'{label:9}{status["level"]:6}{status["message"]}'
    return textwrap.wrap(line, width, subsequent_indent=' ' * 15) if width else [line]


def _key_values(values, width, indent=15):
    """``key=value`` pairs wrapped to ``width`` columns."""
    lines, line = [], ''
    for key, value in values.items():
        item = f'{key}={value}'
        if line and indent + len(line) + 2 + len(item) > width:
            lines.append(' ' * indent + line)
            line = ''
        line = f'{line}  {item}' if line else item
    if line:
        lines.append(' ' * indent + line)
    return lines


def _wrapped(sentences, width, indent=9):
    """Each sentence wrapped to ``width`` columns under the label column."""
    pad = ' ' * indent
    return [line for s in sentences
            for line in textwrap.wrap(s, width, initial_indent=pad, subsequent_indent=pad + '  ')]


def render(state, topics, width=99, verbose=False):
    """
    Return the table as a list of text lines wrapped at ``width`` columns.

    The advice is the node's own sentences (the record's, then each axis's: the words
    ``analyze`` uses, :mod:`imu_allan.report.advice`); ``verbose`` adds the raw key-value lists
    of the stream and advice statuses.
    """
    now = time.monotonic()
    ago = {k: f'{now - t:.0f} s ago' for k, t in state.arrived.items()}
    lines = [f'imu_allan monitor: node {state.prefix[:-2]} on {topics["coeffs"]}  '
             f'(estimates {state.received["coeffs"]}, last {ago.get("coeffs", "never")})']
    if state.coeffs is None:
        lines.append('  waiting for the first estimate (the node publishes every '
                     'publish_period seconds once it has data)')
    else:
        shown = [t for t in IEEE_TERMS if t in ('white_noise', 'bias_instability')
                 or any(math.isfinite(v) for v in state.coeffs[:, IEEE_TERMS.index(t), 0])]
        rows = [[axis] + [_cell(state, i, axis, t) for t in shown]
                + [_verdict(state.adequacy, i)] for i, axis in enumerate(AXES)]
        rows.insert(0, ['axis'] + [t.replace('_', ' ') for t in shown] + ['model'])
        widths = [max(len(row[k]) for row in rows) + 2 for k in range(len(rows[0]))]
        lines.append('continuous-time coefficients in conventional units: value [68.3 % '
                     'interval] where resolved, < 95 % upper limit where not yet')
        lines += [''.join(f'{c:{w}}' for c, w in zip(row, widths)).rstrip() for row in rows]
    if state.deviation is not None and state.deviation[0].size:
        tau = state.deviation[0]
        lines.append(f'averaging times: {tau.size}, {tau[0]:.3g} s to {tau[-1]:.4g} s')
    stream = state.status('IMU stream')
    lines += _status_line('stream', stream)
    if stream is not None:
        v = stream['values']
        keep = ('rate_hz', 'expected_rate_hz', 'samples_total', 'samples_used', 'gaps_total',
                'out_of_order_total', 'excluded_share', 'silence_s')
        lines += _key_values(v if verbose else {k: v[k] for k in keep if k in v}, width)
    advice = state.status('recording advice')
    lines += _status_line('advice', advice, width)
    if advice is not None:
        axis_advice = [state.status(f'{axis} advice') for axis in AXES]
        lines += _wrapped([f'{axis}: {s["message"]}' for axis, s in zip(AXES, axis_advice)
                           if s is not None], width)
        if verbose:
            lines += _key_values(advice['values'], width)
    others = {name[len(state.prefix):]: s for name, s in state.statuses.items()
              if not name.endswith(('IMU stream', 'advice'))}
    if others:
        counts = {}
        for s in others.values():
            counts[s['level']] = counts.get(s['level'], 0) + 1
        lines.append(f'{"checks":9}' + ', '.join(f'{n} {lvl}' for lvl, n in counts.items()))
        lines += [f'  {name}: {s["level"]} {s["message"]}'
                  for name, s in others.items() if s['level'] != 'OK']
    return lines


def _cell(state, i, axis, term):
    """Return a table cell: the resolved value with its interval, else the limit, else -."""
    stats = state.coeffs[i, IEEE_TERMS.index(term)]
    if math.isfinite(stats[0]) or state.limits is None:
        return format_interval(axis, term, stats)
    limit = state.limits[i, IEEE_TERMS.index(term)]
    if not math.isfinite(limit):
        return '-'
    value, unit = conventional(axis, term, limit)
    return f'< {value:.3g} {unit}'


def _verdict(adequacy, i):
    """Return the adequacy of axis ``i`` in a word: fits, DOES NOT FIT, not tested, or -."""
    if adequacy is None:
        return '-'
    p = float(adequacy[i])
    if not math.isfinite(p):
        return 'not tested'
    return 'fits' if p >= ADEQUACY_LEVEL else 'DOES NOT FIT'


def _topic_names(node):
    """Fully qualified names the node's subscriptions resolve to (after remapping)."""
    return {key: node.resolve_topic_name(name) for key, name in
            zip(('coeffs', 'deviation', 'diagnostics'), TOPICS)}


def _emit(out, state, topics, args, tty):
    if args.json:
        out.write(strict_json.dumps(state.snapshot(topics)) + '\n')
    elif tty:  # lines cut at the terminal's width, so a redraw never scrolls
        width = shutil.get_terminal_size((99, 24)).columns
        lines = [line[:width] for line in render(state, topics, min(width, 99), args.verbose)]
        out.write(REDRAW + '\n'.join(lines) + '\n')
    else:
        out.write('\n'.join(render(state, topics, verbose=args.verbose)) + '\n\n')
    out.flush()


@guarded
def main(argv=None):
    """Entry point of ``monitor``."""
    own, ros_argv = split_ros_args(argv)
    args = build_parser().parse_args(own)
    if args.timeout <= 0:
        raise InputError('--timeout', f'must be positive, got {args.timeout:g}')
    if args.duration < 0:
        raise InputError('--duration', f'must be 0 (no limit) or positive, got {args.duration:g}')
    from diagnostic_msgs.msg import DiagnosticArray
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import Float64MultiArray

    context = rclpy.Context()
    # Ctrl-C only sets a flag that the loop checks (spin_once wakes every 0.1 s), so the node
    # and the context are torn down once, in order, by the finally below.  rclpy's own handler
    # would shut the context down from its signal thread at the same time, and a
    # KeyboardInterrupt raised inside rclpy's C++ wait surfaced as a pybind11 cast error
    # (a traceback, seen under load).
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(args=['monitor', *ros_argv], context=context,
               signal_handler_options=SignalHandlerOptions.NO)
    node = None
    try:
        node = rclpy.create_node(f'allan_monitor_{os.getpid()}', namespace=args.namespace,
                                 context=context, start_parameter_services=False)
        state = MonitorState(args.node)
        node.create_subscription(Float64MultiArray, TOPICS[0], state.on_coeffs, 10)
        node.create_subscription(Float64MultiArray, TOPICS[1], state.on_deviation, 10)
        node.create_subscription(DiagnosticArray, TOPICS[2], state.on_diagnostics, 50)
        topics = _topic_names(node)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            return _loop(executor, state, topics, args, sys.stdout, stop)
        except (KeyboardInterrupt, ExternalShutdownException):
            return 0
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)


def _loop(executor, state, topics, args, out, stop):
    tty = out.isatty() and not args.json
    start = time.monotonic()

    def running():
        return executor.context.ok() and not stop.is_set()
    if args.once:
        end = start + args.timeout
        while state.coeffs is None and time.monotonic() < end and running():
            executor.spin_once(timeout_sec=0.1)
        if state.coeffs is None and stop.is_set():
            return 0
        if state.coeffs is None:
            sys.stderr.write(f'monitor: no coefficients on {topics["coeffs"]} within '
                             f'{args.timeout:g} s (is an allan node running there, on this '
                             f'ROS_DOMAIN_ID?)\n')
            return 1
        first = state.received['diagnostics']
        grace = time.monotonic() + DIAGNOSTICS_GRACE_S
        while state.received['diagnostics'] == first and time.monotonic() < grace:
            executor.spin_once(timeout_sec=0.05)
        _emit(out, state, topics, args, False)
        return 0
    shown, shown_coeffs, last_draw, pending = -1, 0, 0.0, None
    while running() and (not args.duration or time.monotonic() - start < args.duration):
        executor.spin_once(timeout_sec=0.1)
        now = time.monotonic()
        if tty:  # redraw on news, and each second for the ages
            if state.version != shown or now - last_draw >= 1.0:
                _emit(out, state, topics, args, True)
                shown, last_draw = state.version, now
            continue
        # plain lines: one block per new estimate, with that cycle's diagnostics when they come
        if state.received['coeffs'] != shown_coeffs and pending is None:
            pending = now
        if pending is not None and (state.arrived.get('diagnostics', 0.0) >= pending
                                    or now - pending > DIAGNOSTICS_GRACE_S):
            shown_coeffs, pending = state.received['coeffs'], None
            _emit(out, state, topics, args, False)
    return 0
