"""Deterministic single-threaded executor on virtual time.

Scheduling mirrors rclpy's ``Executor._wait_for_ready_callbacks`` (rclpy/executors.py,
Humble): one "wait" collects every ready entity, then the handlers run one per
``spin_once`` in a fixed order -- nodes in the order they were added, within a node timers
(creation order) before subscriptions (creation order), one message per subscription per
wait.  When nothing is ready the virtual clock jumps to the earliest deadline of a timer
whose clock follows virtual time (STEADY, SYSTEM, and ROS clocks without an active
``use_sim_time`` override); timers on an overridden ROS clock become ready only when a
/clock message moves that node's ROS time, exactly as rcl's jump callback wakes them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sma_wrist.runtime.vclock import VCLOCK

from .utilities import get_default_context, timeout_sec_to_nsec


class ExternalShutdownException(Exception):
    """Context has been shutdown."""


class ShutdownException(Exception):
    """Signal that executor was shut down."""


class TimeoutException(Exception):
    """Signal that a timeout occurred."""


class ConditionReachedException(Exception):
    """Future has been completed."""


NEVER = 2**63 - 1


class Executor:
    def __init__(self, *, context: Any = None) -> None:
        self._context = get_default_context() if context is None else context
        self._nodes: list[Any] = []
        self._is_shutdown = False
        self._pending: list[Any] = []
        self._pending_idx = 0
        self._cache_version = -1
        self._timers: list[Any] = []
        self._subs: list[Any] = []
        self._groups: list[tuple[list[Any], list[Any]]] = []  # per node: (timers, subscriptions)
        self.callbacks_run = 0

    @property
    def context(self) -> Any:
        return self._context

    def add_node(self, node: Any) -> bool:
        if node not in self._nodes:
            self._nodes.append(node)
            node._executor = self
            self._cache_version = -1
            return True
        return False

    def remove_node(self, node: Any) -> None:
        if node in self._nodes:
            self._nodes.remove(node)
            if node._executor is self:
                node._executor = None
            self._cache_version = -1
            self._pending = []  # drop the rest of the current wait; it is re-collected
            self._pending_idx = 0

    def get_nodes(self) -> list[Any]:
        return list(self._nodes)

    def wake(self) -> None:
        pass

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        self._is_shutdown = True
        for node in list(self._nodes):
            self.remove_node(node)
        return True

    # -- internals ---------------------------------------------------------
    def _refresh(self) -> None:
        version = self._context.graph.version
        if version == self._cache_version:
            return
        timers: list[Any] = []
        groups: list[tuple[list[Any], list[Any]]] = []
        for node in self._nodes:
            groups.append((list(node._timers), list(node._subscriptions)))
            timers.extend(node._timers)
        self._groups = groups
        self._timers = timers
        self._cache_version = version

    def _collect(self) -> list[tuple[bool, Any]]:
        """One 'wait': every ready entity, in execution order (per node: timers, then subscriptions)."""
        self._refresh()
        delivery = self._context.graph.delivery
        if delivery is not None:
            delivery.deliver_due(VCLOCK.steady_ns)
        ready = []
        for timers, subs in self._groups:
            for t in timers:
                if not t._canceled and t._clock._now_ns() >= t._next_call:
                    ready.append((True, t))
            for s in subs:
                if s._queue:
                    ready.append((False, s))
        return ready

    def _next_deadline(self) -> int:
        """Virtual steady time of the earliest deadline of a virtual-time timer (or NEVER)."""
        self._refresh()
        best = NEVER
        for t in self._timers:
            if t._canceled:
                continue
            clock = t._clock
            if not clock._follows_virtual_clock():
                continue
            d = t._next_call - clock._virtual_offset_ns()
            if d < best:
                best = d
        delivery = self._context.graph.delivery
        due = delivery.next_due_ns() if delivery is not None else None
        return best if due is None else min(best, due)

    def _execute(self, entry: tuple[bool, Any]) -> None:
        is_timer, e = entry
        if is_timer:
            if e._call() and e.callback is not None:
                self.callbacks_run += 1
                e.callback()
        else:
            q = e._queue
            if q:
                msg = q.popleft()
                self.callbacks_run += 1
                e.callback(msg)

    def _check_shutdown(self) -> None:
        if self._is_shutdown or not self._context.ok():
            raise ExternalShutdownException()

    # -- rclpy API ---------------------------------------------------------
    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run one ready callback, first jumping virtual time by at most timeout_sec."""
        self._check_shutdown()
        if self._pending_idx < len(self._pending):
            entry = self._pending[self._pending_idx]
            self._pending_idx += 1
            self._execute(entry)
            return
        ready = self._collect()
        if not ready:
            timeout_ns = timeout_sec_to_nsec(timeout_sec)
            deadline = self._next_deadline()
            if timeout_ns < 0:
                if deadline == NEVER:
                    return  # nothing could ever become ready: do not block forever
                VCLOCK.advance_to(deadline)
            else:
                target = VCLOCK.steady_ns + timeout_ns
                VCLOCK.advance_to(min(deadline, target))
            ready = self._collect()
            if not ready:
                return
        self._pending = ready
        self._pending_idx = 1
        self._execute(ready[0])

    def spin(self) -> None:
        while self._context.ok() and not self._is_shutdown:
            before = (VCLOCK.steady_ns, self.callbacks_run)
            self.spin_once()
            if (VCLOCK.steady_ns, self.callbacks_run) == before and not self._pending_rest():
                return  # idle forever: rclpy would block; we return (doc/explanation/runtime.md)

    def _pending_rest(self) -> bool:
        return self._pending_idx < len(self._pending)

    def spin_until_future_complete(self, future: Any, timeout_sec: float | None = None) -> None:
        raise NotImplementedError('futures are not part of the embedded runtime subset')

    def run_until(
        self,
        t_end_ns: int | None = None,
        *,
        stop_when: Callable[[], bool] | None = None,
        max_callbacks: int | None = None,
    ) -> str:
        """Run every event with virtual steady time <= t_end_ns.

        Stops early, after the callback that made it true, when ``stop_when()`` returns
        True, after ``max_callbacks`` callbacks, or when the context is shut down.  On a
        normal end the virtual clock is left at ``t_end_ns``.  Returns the reason:
        ``'time'``, ``'condition'``, ``'max_callbacks'``, ``'idle'`` or ``'shutdown'``.
        """
        end = NEVER if t_end_ns is None else int(t_end_ns)
        limit = NEVER if max_callbacks is None else self.callbacks_run + max_callbacks
        ctx = self._context
        execute = self._execute
        # finish a batch a previous spin_once started
        while self._pending_idx < len(self._pending):
            entry = self._pending[self._pending_idx]
            self._pending_idx += 1
            execute(entry)
        while True:
            if not ctx.ok() or self._is_shutdown:
                return 'shutdown'
            if stop_when is not None and stop_when():
                return 'condition'
            if VCLOCK.steady_ns > end:
                # callbacks moved the clock past the end themselves (a tick that costs more than its
                # period, as a slow machine would): a timer is then ready at every scan, so the
                # deadline check below is never reached
                return 'time'
            ready = self._collect()
            if ready:
                for entry in ready:
                    execute(entry)
                    if stop_when is not None and stop_when():
                        return 'condition'
                    if self.callbacks_run >= limit:
                        return 'max_callbacks'
                continue
            deadline = self._next_deadline()
            if deadline > end or deadline == NEVER:  # NEVER: nothing can become ready (with end NEVER too)
                if end != NEVER:
                    VCLOCK.advance_to(end)
                    return 'time'
                return 'idle'
            VCLOCK.advance_to(deadline)


class SingleThreadedExecutor(Executor):
    pass


class MultiThreadedExecutor(Executor):
    """Accepted for compatibility; runs single-threaded (deterministic)."""

    def __init__(self, num_threads: int | None = None, *, context: Any = None) -> None:
        super().__init__(context=context)
