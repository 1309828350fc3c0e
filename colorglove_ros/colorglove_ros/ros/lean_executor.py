"""A single-threaded executor that waits on its nodes' entities without rebuilding the wait set
in Python on every wake: :class:`LeanExecutor`, what ``run_node`` spins every node with.

rclpy's ``SingleThreadedExecutor`` gathers every entity of every node, makes a new wait set,
wraps each ready callback in a ``Task`` and, after each callback, triggers its own guard
condition, which wakes the next wait at once for nothing: two wait-set builds per message.
This executor keeps the entity lists and the wait set until a node gains or loses an entity,
refills the wait set (the C side empties the entries that were not ready) and runs every
ready callback in the waiting thread. Same callbacks, same semantics for a node of this
package: subscriptions, timers, services (the parameter services ``ros2 param`` uses),
clients, guard conditions and waitables (QoS event handlers); callback groups that refuse
an entity (``TakenOnDemand``) keep it out of the wait set. Coroutine callbacks and tasks made
with ``create_task`` are left to rclpy's own loop."""
from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor, TimeoutObject
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.utilities import timeout_sec_to_nsec

__all__ = ['LeanExecutor']


class _Entities:
    """The waitable entities of some nodes, grouped for the wait set, with its counts."""

    def __init__(self, nodes: list[Any], extra_guards: list[Any]) -> None:
        def wanted(entities: Any) -> list[Any]:
            return [e for e in entities if e.callback_group.can_execute(e)]

        self.subscriptions = [s for n in nodes for s in wanted(n.subscriptions)]
        self.timers = [t for n in nodes for t in wanted(n.timers)]
        self.clients = [c for n in nodes for c in wanted(n.clients)]
        self.services = [s for n in nodes for s in wanted(n.services)]
        self.node_guards = [g for n in nodes for g in wanted(n.guards)]
        self.waitables = [w for n in nodes for w in wanted(n.waitables)]
        self.guards = self.node_guards + extra_guards
        self.key = _entity_key(nodes)

    def wait_set(self, context: Any) -> Any:
        """A wait set sized for these entities."""
        counts = [len(self.subscriptions), len(self.guards), len(self.timers),
                  len(self.clients), len(self.services), 0]
        for waitable in self.waitables:
            extra = waitable.get_num_entities()
            counts = [a + b for a, b in zip(counts, (
                extra.num_subscriptions, extra.num_guard_conditions, extra.num_timers,
                extra.num_clients, extra.num_services, extra.num_events), strict=True)]
        return _rclpy.WaitSet(*counts, context.handle)

    def fill(self, wait_set: Any) -> None:
        """Put every entity into ``wait_set`` (emptied first)."""
        wait_set.clear_entities()
        for subscription in self.subscriptions:
            wait_set.add_subscription(subscription.handle)
        for guard in self.guards:
            wait_set.add_guard_condition(guard.handle)
        for timer in self.timers:
            wait_set.add_timer(timer.handle)
        for client in self.clients:
            wait_set.add_client(client.handle)
        for service in self.services:
            wait_set.add_service(service.handle)
        for waitable in self.waitables:
            waitable.add_to_wait_set(wait_set)


def _entity_key(nodes: list[Any]) -> tuple:
    """What changes when a node gains or loses an entity (the lists are then gathered again)."""
    return tuple((id(n), len(n._subscriptions), len(n._timers), len(n._clients),
                  len(n._services), len(n._guards), sum(1 for _ in n.waitables))
                 for n in nodes)


class LeanExecutor(SingleThreadedExecutor):
    """Runs callbacks in the thread that spins, from a wait set kept between wakes (module
    docstring)."""

    def __init__(self, *, context: Any = None) -> None:
        super().__init__(context=context)
        self._entities: _Entities | None = None
        self._lean_wait_set: Any = None

    def _spin_once_impl(self, timeout_sec: float | TimeoutObject | None = None,
                        wait_condition: Callable[[], bool] = lambda: False) -> None:
        if self._tasks:             # create_task, coroutines: rclpy's own loop runs them
            super()._spin_once_impl(timeout_sec, wait_condition)
            return
        with ExitStack() as valid:
            # the executor's guard conditions and the context stay valid while waiting:
            # shutdown() from another thread triggers the guard, then destroys it once the
            # wait has woken
            with self._shutdown_lock:
                if self._is_shutdown or wait_condition():
                    return
                guards = [self._guard, self._sigint_gc]
                for handle in (guards[0].handle, guards[1].handle, self._context.handle):
                    valid.enter_context(handle)
            nodes = self.get_nodes()
            if self._entities is None or self._entities.key != _entity_key(nodes):
                self._entities = _Entities(nodes, guards)
                self._lean_wait_set = self._entities.wait_set(self._context)
            entities, wait_set = self._entities, self._lean_wait_set
            entities.fill(wait_set)
            wait_set.wait(timeout_sec_to_nsec(
                timeout_sec.timeout if isinstance(timeout_sec, TimeoutObject) else timeout_sec))
        if self._is_shutdown:
            return
        if not self._context.ok():
            raise ExternalShutdownException()
        self._run_ready(entities, wait_set)

    def _run_ready(self, entities: _Entities, wait_set: Any) -> None:
        """Run the callback of every entity ``wait_set`` found ready."""
        ready_waitables = [w for w in entities.waitables if w.is_ready(wait_set)]
        timers_ready = set(wait_set.get_ready_entities('timer'))
        subscriptions_ready = set(wait_set.get_ready_entities('subscription'))
        guards_ready = set(wait_set.get_ready_entities('guard_condition'))
        clients_ready = set(wait_set.get_ready_entities('client'))
        services_ready = set(wait_set.get_ready_entities('service'))
        for waitable in ready_waitables:
            self._run(waitable, self._take_waitable)
        for timer in entities.timers:
            if timer.handle.pointer in timers_ready and timer.handle.is_timer_ready():
                self._run(timer, self._take_timer)
        for subscription in entities.subscriptions:
            if subscription.handle.pointer in subscriptions_ready:
                self._run(subscription, self._take_subscription)
        for guard in entities.node_guards:
            if guard.handle.pointer in guards_ready:
                guard._executor_triggered = True
                self._run(guard, self._take_guard_condition)
        for client in entities.clients:
            if client.handle.pointer in clients_ready:
                self._run(client, self._take_client)
        for service in entities.services:
            if service.handle.pointer in services_ready:
                self._run(service, self._take_service)

    def _run(self, entity: Any, take: Callable[[Any], Any]) -> None:
        """Take ``entity``'s work and run its callback to the end, in its callback group."""
        group = entity.callback_group
        if not group.beginning_execution(entity):
            return
        try:
            execute = take(entity)
            if execute is None:
                return
            coroutine = execute()
            try:
                coroutine.send(None)
            except StopIteration:
                return
            coroutine.close()
            raise RuntimeError(f'{type(self).__name__} runs synchronous callbacks only: '
                               f'{entity!r} awaited; spin it with rclpy\'s executors')
        finally:
            group.ending_execution(entity)
