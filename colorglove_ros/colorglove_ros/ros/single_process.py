"""The tracker's nodes in one process: camera_node (unless ``--no-camera``), segmentation_node,
lookup_node and ik_node, each the same node class as its own executable, on one
multi-threaded executor (after ros2/examples' ``composed.py``).

``colorglove_single_process [--no-camera] [--threads N] --ros-args --params-file
config/nodes.yaml ...``: the ROS arguments (parameter files, ``-p``, ``-r``) apply to every node
in the process, so a parameter file keyed by node name (``/**/segmentation``, ...) configures each
as it would its own process. The four separate processes stay the default (``colorglove_launch
config/pipeline.launch.yaml``); this is for users who prefer one process. Messages between the
nodes still go through the middleware."""
from __future__ import annotations

import argparse
import sys

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node

from colorglove_ros.ros.nodes.common import (
    StartupError,
    ending_on_shutdown,
    freeze_startup_objects,
    prepare_node_process,
)

__all__ = ['DEFAULT_THREADS', 'node_classes', 'main']

DEFAULT_THREADS = 4     # one per node: each node's callbacks stay mutually exclusive


def node_classes(with_camera: bool) -> list[type[Node]]:
    """The node classes to start, in pipeline order."""
    from colorglove_ros.ros.nodes.camera_node import CameraNode
    from colorglove_ros.ros.nodes.ik_node import IKNode
    from colorglove_ros.ros.nodes.lookup_node import LookupNode
    from colorglove_ros.ros.nodes.segmentation_node import SegmentationNode

    return [CameraNode] * with_camera + [SegmentationNode, LookupNode, IKNode]


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``colorglove_single_process``."""
    argv = sys.argv[1:] if argv is None else list(argv)
    split = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--no-camera', action='store_true',
                        help='no camera_node: images come from a driver or a bag')
    parser.add_argument('--threads', type=int, default=DEFAULT_THREADS,
                        help='executor threads (default: %(default)s)')
    args = parser.parse_args(argv[:split])
    prepare_node_process()
    rclpy.init(args=['colorglove_single_process', *argv[split:]])
    nodes: list[Node] = []
    executor = MultiThreadedExecutor(num_threads=max(1, args.threads))
    try:
        with ending_on_shutdown():
            for cls in node_classes(not args.no_camera):
                nodes.append(cls())
                executor.add_node(nodes[-1])
            freeze_startup_objects()
            executor.spin()
    except StartupError as exc:
        print(f'[FATAL] {exc}', flush=True)
        return 1
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
