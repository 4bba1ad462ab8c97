"""Default context handling (as rclpy/utilities.py, Humble)."""

from __future__ import annotations

from collections.abc import Iterable

from sma_wrist.runtime.arguments import remove_ros_args as _remove_ros_args

from .context import Context

g_default_context: Context | None = None


def get_default_context(*, shutting_down: bool = False) -> Context:
    """Return the global default context (a new one after the previous was shut down)."""
    global g_default_context
    if g_default_context is None:
        g_default_context = Context()
    if shutting_down:
        old, g_default_context = g_default_context, None
        return old
    return g_default_context


def ok(*, context: Context | None = None) -> bool:
    return (context or get_default_context()).ok()


def shutdown(*, context: Context | None = None) -> None:
    if context is None:
        context = get_default_context(shutting_down=True)
    context.shutdown()


def try_shutdown(*, context: Context | None = None) -> None:
    global g_default_context
    if context is None:
        context = get_default_context()
        context.try_shutdown()
        if not context.ok():
            g_default_context = None
    else:
        context.try_shutdown()


def remove_ros_args(args: Iterable[str] | None = None) -> list[str]:
    import sys

    return _remove_ros_args(sys.argv if args is None else args)


def get_rmw_implementation_identifier() -> str:
    return 'sma_wrist_embedded'


def timeout_sec_to_nsec(timeout_sec: float | None) -> int:
    if timeout_sec is None or timeout_sec < 0:
        return -1
    return int(float(timeout_sec) * 1e9)
