"""
Shared plumbing for the rclpy nodes.

``--help`` without ROS, the Jazzy spin/shutdown pattern, parameter descriptors and diagnostic
status building.
"""

from dataclasses import dataclass
import math
import sys
from typing import Union

# rclpy is imported lazily inside the functions that need it, so ``--help`` answers instantly
# and this module can be imported by tests that only build parameter descriptions.


def handle_help(executable, description, parameters, argv=None):
    """
    Print a help text and exit 0 when ``-h``/``--help`` comes before ``--ros-args``.

    ``parameters`` is the node's :class:`Param` table.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    if not ({'-h', '--help'} & set(argv)):
        return
    lines = [f'usage: ros2 run imu_allan {executable} [--ros-args -p NAME:=VALUE ...]', '',
             description, '', 'parameters:']
    for param in parameters:
        extra = f', range {param.range[0]:g}..{param.range[1]:g}' if param.range else ''
        lines.append(f'  {param.name} (default {param.default!r}{extra}): {param.description}')
    print('\n'.join(lines))
    sys.exit(0)


def diagnostic_status(name, level, message, hardware_id='', values=None):
    """
    Build a ``diagnostic_msgs/DiagnosticStatus``; ``level`` is 0 OK, 1 WARN, 2 ERROR, 3 STALE.

    ``values`` is a mapping turned into string key/value pairs (floats with 6 significant
    digits).
    """
    from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
    status = DiagnosticStatus()
    status.level = bytes([int(level)])
    status.name = name
    status.message = message
    status.hardware_id = hardware_id
    for key, value in (values or {}).items():
        text = f'{value:.6g}' if isinstance(value, float) else str(value)
        status.values.append(KeyValue(key=str(key), value=text))
    return status


def run_node(node_factory, args=None):
    """Init rclpy, build the node, spin until shutdown: the ros2/demos Jazzy pattern."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # rclpy's SIGINT handler can shut the context down while spin() builds its wait set;
        # that surfaces as RCLError('context is not valid'): a shutdown, not a fault (seen
        # under load in the driver's end-to-end tests).  With the context alive, it is a bug.
        if rclpy.ok():
            raise
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()


def node_main(executable, description, parameters, factory, args=None):
    """
    Entry point of a node: ``--help`` without spinning, then spin; bad parameters exit 2.

    ``parameters`` is the node's :class:`Param` table; ``factory`` builds the node.  A refused
    parameter prints one line naming it (no traceback).
    """
    from rclpy.exceptions import ParameterException

    from ..errors import InputError
    handle_help(executable, description, parameters)
    try:
        run_node(factory, args)
    except (InputError, ParameterException) as exc:
        lines = str(exc).splitlines() or [type(exc).__name__]
        print(f'{executable}: {lines[0]}', file=sys.stderr)  # one line, no traceback
        sys.exit(2)


@dataclass(frozen=True)
class Param:
    """
    One row of a node's parameter table (the one format every node uses).

    ``range`` is ``(low, high)`` for numbers (a float parameter also accepts an integer on the
    command line, ``-p rate_hz:=200``), ``choices`` the allowed values, ``read_only`` refuses
    changes at run time.
    """

    name: str
    default: Union[bool, int, float, str]
    description: str
    range: tuple = None  # noqa: A003 - the descriptor's own word
    read_only: bool = False
    choices: tuple = None


def check_value(param, value):
    """Return ``value`` coerced to the parameter's type and checked; raise InputError."""
    from ..errors import InputError
    kind = type(param.default)
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(param.name, f'must be a number, got {value!r}')
        value = float(value)
        if not math.isfinite(value):
            raise InputError(param.name, f'must be finite, got {value!r}')
    elif kind is int and (isinstance(value, bool) or not isinstance(value, int)):
        raise InputError(param.name, f'must be an integer, got {value!r}')
    elif kind in (bool, str) and not isinstance(value, kind):
        raise InputError(param.name, f'must be a {kind.__name__}, got {value!r}')
    if param.range is not None and not param.range[0] <= value <= param.range[1]:
        raise InputError(param.name, f'{value:g} is outside [{param.range[0]:g}, '
                                     f'{param.range[1]:g}]')
    if param.choices is not None and value not in param.choices:
        raise InputError(param.name, f'{value!r} is not one of '
                                     f'{", ".join(map(str, param.choices))}')
    return value


def declare_parameter_table(node, table):
    """
    Declare every :class:`Param` with a descriptor; return the checked values as a dict.

    Raises InputError (the node's ``main`` prints it as one line, exit status 2) for a value
    given on the command line or in a parameter file that the table refuses.
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
    values = {}
    for param in table:
        kwargs = {}
        low, high = param.range or (None, None)
        if isinstance(param.default, float):
            # dynamic typing, so that an integer given for a float (-p rate_hz:=200) is taken;
            # the range is then checked by check_value, not by rclpy
            kwargs['dynamic_typing'] = True
            if param.range is not None:
                kwargs['floating_point_range'] = [FloatingPointRange(
                    from_value=float(low), to_value=float(high), step=0.0)]
        elif param.range is not None and isinstance(param.default, int) \
                and not isinstance(param.default, bool):
            kwargs['integer_range'] = [IntegerRange(from_value=int(low), to_value=int(high),
                                                    step=1)]
        elif isinstance(param.default, list):
            # dynamic typing: a string array or one comma-separated string
            # (-p estimators:=oadev,mdev); the node's own check parses and validates it
            kwargs['dynamic_typing'] = True
        if param.choices is not None:
            kwargs['additional_constraints'] = 'one of ' + ', '.join(map(str, param.choices))
        node.declare_parameter(param.name, param.default, ParameterDescriptor(
            description=param.description, read_only=param.read_only, **kwargs))
        values[param.name] = check_value(param, node.get_parameter(param.name).value)
    return values


def validate_on_set(params, table, check=None):
    """
    Return an on-set-parameters callback: each change checked by its table row, then ``check``.

    ``params`` is the node's current dict; ``check(candidate dict)`` does cross-field checks
    and raises InputError with the reason.  Names outside the table (QoS overrides) pass.
    """
    from rcl_interfaces.msg import SetParametersResult

    from ..errors import InputError
    rows = {p.name: p for p in table}

    def on_set(changes):
        candidate = dict(params)
        try:
            for change in changes:
                if change.name in rows:
                    candidate[change.name] = check_value(rows[change.name], change.value)
            if check is not None:
                check(candidate)
        except InputError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)
    return on_set


def apply_changes(params, table, changes):
    """Post-set: store the accepted changes (coerced) in ``params``; return the changed names."""
    rows = {p.name: p for p in table}
    changed = set()
    for change in changes:
        if change.name in rows:
            params[change.name] = check_value(rows[change.name], change.value)
            changed.add(change.name)
    return changed


def sensor_publisher(node, msg_type, topic):
    """Return a publisher with sensor-data QoS and QoS overrides enabled (``qos_overrides.``)."""
    from rclpy.qos import qos_profile_sensor_data
    from rclpy.qos_overriding_options import QoSOverridingOptions
    overrides = QoSOverridingOptions.with_default_policies()
    return node.create_publisher(msg_type, topic, qos_profile_sensor_data,
                                 qos_overriding_options=overrides)


def log(node, level, text):
    """Log ``text`` at ``level`` ('info', 'warn', 'error') on the node's logger."""
    # One call site per severity: rclpy refuses to change the severity of a call site.
    logger = node.get_logger()
    if level == 'info':
        logger.info(text)
    elif level == 'warn':
        logger.warning(text)
    else:
        logger.error(text)


def polled_subscription(node, msg_type, topic, depth, overrides=True, raw=False):
    """
    Return a deep sensor-data subscription that the executor never waits on.

    Messages queue in the middleware and a timer takes them in batches with
    :func:`take_batch`: at 1 kHz this costs a few percent of a core where one executor callback
    per message costs ~20 % (measured, docs/online.md).  With ``raw`` the batch holds the
    serialized bytes (decode them with :func:`imu_allan.formats.imu_cdr.cdr_to_arrays`).
    """
    from rclpy.callback_groups import CallbackGroup
    from rclpy.qos import (
        qos_profile_sensor_data,
        QoSDurabilityPolicy,
        QoSHistoryPolicy,
        QoSProfile,
    )
    from rclpy.qos_overriding_options import QoSOverridingOptions

    class PolledGroup(CallbackGroup):
        """A callback group the executor never runs."""

        def can_execute(self, entity):
            return False

        def beginning_execution(self, entity):
            return False

        def ending_execution(self, entity):
            pass

    qos = QoSProfile(history=QoSHistoryPolicy.KEEP_LAST, depth=int(depth),
                     reliability=qos_profile_sensor_data.reliability,
                     durability=QoSDurabilityPolicy.VOLATILE)
    kwargs = {}
    if overrides:
        kwargs['qos_overriding_options'] = QoSOverridingOptions.with_default_policies()
    return node.create_subscription(msg_type, topic, lambda _msg: None, qos,
                                    callback_group=PolledGroup(), raw=raw, **kwargs)


def take_batch(sub, max_batch):
    """Take up to ``max_batch`` queued messages from a polled subscription."""
    msgs = []
    with sub.handle:
        for _ in range(max_batch):
            taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                break
            msgs.append(taken[0])
    return msgs
