"""LeanExecutor (every node's executor, ``run_node``): the same callbacks as rclpy's
single-threaded executor (messages, timers, the parameter services ``ros2 param`` uses, tasks),
a TakenOnDemand subscription never run, and the wait set kept between wakes until a node
gains an entity."""
from __future__ import annotations

import threading
import time

import pytest
import rclpy
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.parameter import Parameter
from std_msgs.msg import String

from colorglove_ros.ros.lean_executor import LeanExecutor
from colorglove_ros.ros.nodes.common import LATEST_ONLY, TakenOnDemand, take_message


@pytest.fixture
def context(ros_context: rclpy.Context) -> rclpy.Context:
    """The test's own rclpy context (``ros_context``, test/conftest.py)."""
    return ros_context


def _spin_until(executor: LeanExecutor, done, timeout_s: float = 5.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)


def test_messages_timers_and_parameter_services(context: rclpy.Context) -> None:
    node = rclpy.create_node('lean_node', context=context)
    other = rclpy.create_node('lean_other', context=context)
    executor = LeanExecutor(context=context)
    try:
        node.declare_parameter('gain', 3)
        got: list[str] = []
        ticks: list[int] = []
        node.create_subscription(String, 'lean_topic', lambda msg: got.append(msg.data),
                                 LATEST_ONLY)
        node.create_timer(0.02, lambda: ticks.append(1))
        executor.add_node(node)
        publisher = other.create_publisher(String, 'lean_topic', LATEST_ONLY)
        _spin_until(executor, lambda: publisher.get_subscription_count() > 0)
        publisher.publish(String(data='hello'))
        _spin_until(executor, lambda: got and len(ticks) >= 3)
        assert got == ['hello'] and len(ticks) >= 3

        # the parameter services answer while the node spins (ros2 param get / set); the
        # clients' node spins on the same executor (their responses are its callbacks)
        executor.add_node(other)
        get = other.create_client(GetParameters, '/lean_node/get_parameters')
        put = other.create_client(SetParameters, '/lean_node/set_parameters')
        _spin_until(executor, lambda: get.service_is_ready() and put.service_is_ready())
        answer = get.call_async(GetParameters.Request(names=['gain']))
        _spin_until(executor, answer.done)
        assert answer.result().values[0].integer_value == 3
        changed = put.call_async(SetParameters.Request(
            parameters=[Parameter('gain', value=5).to_parameter_msg()]))
        _spin_until(executor, changed.done)
        assert changed.result().results[0].successful
        assert node.get_parameter('gain').value == 5
    finally:
        executor.shutdown()
        node.destroy_node()
        other.destroy_node()


def test_wait_set_kept_between_wakes_and_rebuilt_for_a_new_entity(context: rclpy.Context
                                                                   ) -> None:
    node = rclpy.create_node('lean_keep', context=context)
    executor = LeanExecutor(context=context)
    try:
        executor.add_node(node)
        executor.spin_once(timeout_sec=0.0)
        kept = executor._lean_wait_set
        for _ in range(3):
            executor.spin_once(timeout_sec=0.0)
        assert executor._lean_wait_set is kept
        # an entity made while spinning joins the wait set and is run
        got: list[str] = []
        node.create_subscription(String, 'lean_late', lambda msg: got.append(msg.data),
                                 LATEST_ONLY)
        publisher = node.create_publisher(String, 'lean_late', LATEST_ONLY)
        publisher.publish(String(data='late'))
        _spin_until(executor, lambda: got)
        assert got == ['late'] and executor._lean_wait_set is not kept
    finally:
        executor.shutdown()
        node.destroy_node()


def test_taken_on_demand_stays_out_and_tasks_still_run(context: rclpy.Context) -> None:
    node = rclpy.create_node('lean_demand', context=context)
    executor = LeanExecutor(context=context)
    try:
        called: list[str] = []
        subscription = node.create_subscription(
            String, 'lean_demand', lambda msg: called.append(msg.data), LATEST_ONLY,
            callback_group=TakenOnDemand())
        publisher = node.create_publisher(String, 'lean_demand', LATEST_ONLY)
        executor.add_node(node)
        publisher.publish(String(data='kept'))
        ran: list[int] = []
        executor.create_task(lambda: ran.append(1))
        _spin_until(executor, lambda: ran)
        for _ in range(5):
            executor.spin_once(timeout_sec=0.02)
        assert ran == [1] and called == []
        assert subscription not in executor._entities.subscriptions
        taken = None
        deadline = time.monotonic() + 5.0
        while taken is None and time.monotonic() < deadline:
            taken = take_message(subscription)
        assert taken.data == 'kept'
    finally:
        executor.shutdown()
        node.destroy_node()


def test_shutdown_ends_a_blocked_spin(context: rclpy.Context) -> None:
    node = rclpy.create_node('lean_stop', context=context)
    executor = LeanExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    spinner.start()
    time.sleep(0.2)
    executor.shutdown()
    spinner.join(5.0)
    node.destroy_node()
    assert not spinner.is_alive()
