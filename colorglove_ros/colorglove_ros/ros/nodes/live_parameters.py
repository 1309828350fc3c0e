"""Parameters a node lets you change while it runs (``ros2 param set``): each comes with a
function that checks a new value through the core's own validation and returns how to apply
it; a batch is applied only when every value in it passed, otherwise it is refused with the
reason. Start-up-only parameters stay read-only (``common.declare``)."""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from colorglove_ros.core.errors import ColorGloveError
from colorglove_ros.ros.nodes.common import declare

__all__ = ['Apply', 'Check', 'LiveParameters']

Apply = Callable[[], None]
"""Applies a checked value."""
Check = Callable[[Any], Apply]
"""Checks a new value (raises a ``ValueError`` or ``ColorGloveError`` saying why not) and
returns how to apply it."""


class LiveParameters:
    """The run-time-settable parameters of ``node``, with one on-set callback for all."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.checks: dict[str, Check] = {}
        node.add_on_set_parameters_callback(self._on_set)

    def declare(self, name: str, default: Any, description: str, check: Check,
                minimum: float | None = None, maximum: float | None = None) -> Any:
        """Declare ``name`` settable at run time (``check`` validates and applies a new value;
        the start value is the caller's to apply); return its start value."""
        value = declare(self.node, name, default, f'{description} (settable at run time)',
                        minimum, maximum, read_only=False)
        self.checks[name] = check
        return value

    def _on_set(self, parameters: list[Parameter]) -> SetParametersResult:
        """Check every value of the batch, then apply them all; or refuse the batch."""
        actions: list[tuple[str, Any, Apply]] = []
        for parameter in parameters:
            check = self.checks.get(parameter.name)
            if check is None:          # read-only ones are refused by rclpy before this
                continue
            try:
                actions.append((parameter.name, parameter.value, check(parameter.value)))
            except (ColorGloveError, ValueError, TypeError) as exc:
                reason = f'{parameter.name} = {parameter.value!r} refused: {exc}'
                self.node.get_logger().warn(reason)
                return SetParametersResult(successful=False, reason=reason)
        for name, value, apply in actions:
            apply()
            self.node.get_logger().info(f'parameter {name} set to {value!r}')
        return SetParametersResult(successful=True)
