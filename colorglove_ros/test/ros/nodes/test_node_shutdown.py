"""A node ends quietly when ROS shuts down under it: once rclpy's SIGINT / SIGTERM handler has
shut the context down, the executor's next wait set and a callback's next publish raise
``RCLError`` ("context is not valid"); that is the end of the spin, not a crash with a
traceback. The same error while the context is valid still propagates."""
from __future__ import annotations

import pytest
import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import ExternalShutdownException

from colorglove_ros.ros.nodes.common import ending_on_shutdown


def test_rcl_error_after_shutdown_ends_the_spin_quietly() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(RCLError), ending_on_shutdown(context):
            raise RCLError('failed to publish: unrelated failure while running')
        rclpy.shutdown(context=context)
        with ending_on_shutdown(context):
            raise RCLError("failed to initialize wait set: the given context is not valid")
        for interrupt in (KeyboardInterrupt, ExternalShutdownException):
            with ending_on_shutdown(context):
                raise interrupt()
    finally:
        rclpy.try_shutdown(context=context)


def test_other_errors_propagate() -> None:
    with pytest.raises(ValueError), ending_on_shutdown():
        raise ValueError('a bug in a callback')


def test_run_node_freezes_the_start_up_heap_once_before_spinning(monkeypatch) -> None:
    """Every node's main (run_node) freezes the objects made at start-up once, after the node
    is built and before it spins: a full collection then walks only what frames make."""
    import gc

    import colorglove_ros.ros.nodes.common as common

    events: list[str] = []
    monkeypatch.setattr(common, 'clean_stale_fastdds_segments', lambda: None)
    monkeypatch.setattr(common.rclpy, 'init', lambda args=None: events.append('init'))
    monkeypatch.setattr(common.rclpy, 'try_shutdown', lambda: events.append('shutdown'))
    monkeypatch.setattr(gc, 'freeze', lambda: events.append('freeze'))

    class Executor:
        def add_node(self, node: object) -> None:
            events.append('added')

        def spin(self) -> None:
            events.append('spin')

        def shutdown(self) -> None:
            events.append('executor shutdown')

    monkeypatch.setattr(common, 'LeanExecutor', Executor)

    class Built:
        def __init__(self) -> None:
            events.append('built')

        def destroy_node(self) -> None:
            events.append('destroyed')

    assert common.run_node(Built) == 0
    assert events == ['init', 'built', 'freeze', 'added', 'spin', 'executor shutdown',
                      'destroyed', 'shutdown']


def test_single_process_prepares_then_freezes_once_after_every_node_is_built(monkeypatch) -> None:
    import gc

    import colorglove_ros.ros.single_process as single

    events: list[str] = []

    class Executor:
        def __init__(self, num_threads: int) -> None:
            pass

        def add_node(self, node: object) -> None:
            events.append('added')

        def spin(self) -> None:
            events.append('spin')

        def shutdown(self) -> None:
            pass

    class Built:
        def __init__(self) -> None:
            events.append('built')

        def destroy_node(self) -> None:
            pass

    monkeypatch.setattr(single, 'prepare_node_process', lambda: events.append('prepared'))
    monkeypatch.setattr(single.rclpy, 'init', lambda args=None: None)
    monkeypatch.setattr(single.rclpy, 'try_shutdown', lambda: None)
    monkeypatch.setattr(single, 'MultiThreadedExecutor', Executor)
    monkeypatch.setattr(single, 'node_classes', lambda with_camera: [Built, Built])
    monkeypatch.setattr(gc, 'freeze', lambda: events.append('freeze'))
    assert single.main(['--no-camera']) == 0
    assert events == ['prepared', 'built', 'added', 'built', 'added', 'freeze', 'spin']
