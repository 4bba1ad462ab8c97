"""Embedded rclpy: the subset of rclpy that sma_wrist nodes use, in one process, on virtual time.

Installed as ``rclpy`` by :func:`sma_wrist.runtime.activate` only where the real rclpy is
not importable.  Function signatures follow rclpy/__init__.py (Humble).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from . import signals as _signals
from .context import Context
from .executors import Executor, SingleThreadedExecutor
from .node import Node
from .utilities import get_default_context, get_rmw_implementation_identifier, ok, remove_ros_args
from .utilities import shutdown as _shutdown
from .utilities import try_shutdown as _try_shutdown

__all__ = [
    'create_node',
    'get_global_executor',
    'init',
    'ok',
    'shutdown',
    'spin',
    'spin_once',
    'try_shutdown',
    'get_default_context',
    'remove_ros_args',
    'get_rmw_implementation_identifier',
    'Node',
    'Context',
]

__embedded__ = True

_global_executor: Executor | None = None


def init(
    *,
    args: Iterable[str] | None = None,
    context: Context | None = None,
    domain_id: int | None = None,
    signal_handler_options: Any = None,
) -> None:
    """Initialize the context (parse --ros-args, reset virtual time to 0)."""
    global _global_executor
    ctx = get_default_context() if context is None else context
    ctx.init(args, domain_id=domain_id)
    if context is None:
        _global_executor = None
    _signals.install_signal_handlers(signal_handler_options)


def shutdown(*, context: Context | None = None, uninstall_handlers: bool | None = None) -> None:
    global _global_executor
    _shutdown(context=context)
    if context is None:
        _global_executor = None
    if uninstall_handlers or (uninstall_handlers is None and context is None):
        _signals.uninstall_signal_handlers()


def try_shutdown(*, context: Context | None = None, uninstall_handlers: bool | None = None) -> None:
    global _global_executor
    _try_shutdown(context=context)
    if context is None:
        _global_executor = None
    if uninstall_handlers or (uninstall_handlers is None and context is None):
        _signals.uninstall_signal_handlers()


def create_node(node_name: str, *, context: Context | None = None, **kwargs: Any) -> Node:
    return Node(node_name, context=context, **kwargs)


def get_global_executor() -> Executor:
    global _global_executor
    if _global_executor is None or _global_executor.context is not get_default_context():
        _global_executor = SingleThreadedExecutor()
    return _global_executor


def spin_once(node: Node, *, executor: Executor | None = None, timeout_sec: float | None = None) -> None:
    executor = get_global_executor() if executor is None else executor
    try:
        executor.add_node(node)
        executor.spin_once(timeout_sec=timeout_sec)
    finally:
        executor.remove_node(node)


def spin(node: Node, executor: Executor | None = None) -> None:
    executor = get_global_executor() if executor is None else executor
    try:
        executor.add_node(node)
        while executor.context.ok():
            before = (executor.callbacks_run,)
            from sma_wrist.runtime.vclock import VCLOCK

            t0 = VCLOCK.steady_ns
            executor.spin_once()
            if executor.callbacks_run == before[0] and VCLOCK.steady_ns == t0 and not executor._pending_rest():
                return  # nothing can ever become ready (rclpy would block forever)
    finally:
        executor.remove_node(node)


def spin_until_future_complete(
    node: Node, future: Any, executor: Executor | None = None, timeout_sec: float | None = None
) -> None:
    raise NotImplementedError('futures are not part of the embedded runtime subset')
