"""Plumbing every node shares: the parameter table, config files, the polled subscription."""

import os
import time

from conftest import DOMAIN, REPO
from imu_allan.errors import InputError
from imu_allan.nodes import allan, denoise, driver
from imu_allan.nodes.common import check_value, Param
import pytest
import yaml

pytestmark = pytest.mark.ros

rclpy = pytest.importorskip('rclpy', reason='rclpy Jazzy wheels missing')


@pytest.mark.parametrize('module', [allan, denoise, driver], ids=['allan', 'denoise', 'driver'])
def test_config_file_sets_exactly_the_declared_defaults(module):
    """config/<node>.yaml (/** key, so it applies in any namespace) sets declared defaults."""
    name = module.__name__.rsplit('.', 1)[-1]
    with open(REPO / 'config' / f'{name}.yaml', encoding='utf-8') as stream:
        params = yaml.safe_load(stream)['/**']['ros__parameters']
    declared = {p.name: p.default for p in module.PARAMETERS}
    assert set(params) <= set(declared)
    for key, value in params.items():
        assert value == declared[key] and type(value) is type(declared[key]), key


def test_one_table_format_for_every_node():
    """Every node's table is made of Param rows; defaults pass their own checks."""
    for module in (allan, denoise, driver):
        for param in module.PARAMETERS:
            assert isinstance(param, Param)
            assert check_value(param, param.default) == param.default, param.name


def test_check_value_coerces_and_refuses():
    """An integer for a float is taken (-p rate_hz:=200); ranges, types and choices refuse."""
    rate = Param('rate_hz', 100.0, 'rate', (1.0, 1000.0))
    assert check_value(rate, 200) == 200.0 and isinstance(check_value(rate, 200), float)
    for bad, words in ((0.5, 'outside'), (True, 'number'), ('x', 'number'),
                       (float('inf'), 'finite')):
        with pytest.raises(InputError, match=words):
            check_value(rate, bad)
    baud = Param('baud', 115200, 'baud', choices=(115200, 921600))
    with pytest.raises(InputError, match='not one of'):
        check_value(baud, 9600)
    with pytest.raises(InputError, match='integer'):
        check_value(baud, 115200.0)


def test_take_batch_uses_rclpy_as_this_package_expects():
    """
    The polled subscription and take_batch (rclpy internals: handle.take_message) work.

    Fails if a future rclpy renames or changes what ``take_batch`` relies on: messages
    published to a polled subscription come back from ``take_batch`` in order, raw or not.
    """
    from imu_allan.nodes.common import polled_subscription, take_batch
    from sensor_msgs.msg import Imu
    os.environ['ROS_DOMAIN_ID'] = str(DOMAIN)
    context = rclpy.context.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('take_batch_test', context=context)
        sub = polled_subscription(node, Imu, 'imu/take_test', 100)
        raw_sub = polled_subscription(node, Imu, 'imu/take_test', 100, raw=True)
        pub = node.create_publisher(Imu, 'imu/take_test', 100)
        deadline = time.monotonic() + 10
        while pub.get_subscription_count() < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        for k in range(20):
            msg = Imu()
            msg.header.stamp.sec = k
            pub.publish(msg)
        got, raw = [], []
        while (len(got) < 20 or len(raw) < 20) and time.monotonic() < deadline:
            got += take_batch(sub, 7)
            raw += take_batch(raw_sub, 7)
            time.sleep(0.02)
        assert [m.header.stamp.sec for m in got] == list(range(20))
        assert len(raw) == 20 and all(isinstance(b, bytes) for b in raw)
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
