"""Shared plumbing for the rclpy nodes.

``--help`` without ROS, the Jazzy spin/shutdown pattern, parameter descriptors and diagnostic
status building.
"""

import sys

# rclpy is imported lazily inside the functions that need it, so ``--help`` answers instantly
# and this module can be imported by tests that only build parameter descriptions.


def handle_help(executable, description, parameters, argv=None):
    """Print a help text and exit 0 when ``-h``/``--help`` comes before ``--ros-args``.

    ``parameters`` is a list of ``(name, default, description)`` tuples.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if '--ros-args' in argv:
        argv = argv[:argv.index('--ros-args')]
    if not ({'-h', '--help'} & set(argv)):
        return
    lines = [f'usage: ros2 run imu_allan {executable} [--ros-args -p NAME:=VALUE ...]', '',
             description, '', 'parameters:']
    for name, default, text in parameters:
        lines.append(f'  {name} (default {default!r}): {text}')
    print('\n'.join(lines))
    sys.exit(0)


def float_range(low, high, step=0.0):
    """A ``FloatingPointRange`` for a parameter descriptor."""
    from rcl_interfaces.msg import FloatingPointRange
    return [FloatingPointRange(from_value=float(low), to_value=float(high), step=float(step))]


def int_range(low, high, step=1):
    """An ``IntegerRange`` for a parameter descriptor."""
    from rcl_interfaces.msg import IntegerRange
    return [IntegerRange(from_value=int(low), to_value=int(high), step=int(step))]


def descriptor(description, read_only=False, **kwargs):
    """A ``ParameterDescriptor`` with a description (and optional ranges)."""
    from rcl_interfaces.msg import ParameterDescriptor
    return ParameterDescriptor(description=description, read_only=read_only, **kwargs)


def diagnostic_status(name, level, message, hardware_id='', values=None):
    """Build a ``diagnostic_msgs/DiagnosticStatus``; ``level`` is 0 OK, 1 WARN, 2 ERROR, 3 STALE.

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
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
