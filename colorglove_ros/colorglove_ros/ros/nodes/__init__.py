"""Thin rclpy node shells around :mod:`colorglove_ros.core`."""
