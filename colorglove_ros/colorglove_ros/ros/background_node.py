"""A node with its own context, spun in a daemon thread: for tools that listen to the graph
they run (stage times, restart outputs) without blocking their own main loop."""
from __future__ import annotations

import threading

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

__all__ = ['BackgroundNode']


class BackgroundNode:
    """``node`` (create subscriptions on it, then :meth:`start`) spun until :meth:`close`."""

    def __init__(self, name: str) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node: Node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)

    def start(self) -> None:
        """Start spinning in the background thread."""
        self.thread.start()

    def close(self) -> None:
        """Stop spinning and release the node and its context."""
        self.executor.shutdown()
        if self.thread.is_alive():
            self.thread.join(timeout=5.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
