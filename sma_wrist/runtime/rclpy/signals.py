"""rclpy.signals for the embedded runtime: what a Ctrl-C does to a node process, as in rclpy (Humble, Jazzy).

rclpy's ``init`` installs a SIGINT handler that shuts every context down and then calls the handler it replaced
(Python's, which raises KeyboardInterrupt). So by the time ``main`` catches the KeyboardInterrupt and destroys its
node, publishing raises ("publisher's context is invalid"). The embedded runtime does the same, so that a node
whose teardown publishes fails here as it fails under ``ros2 run``. SIGTERM is not handled (the default ends the
process, as rclpy's chained handler does).
"""

from __future__ import annotations

import enum
import signal
import threading
from typing import Any


class SignalHandlerOptions(enum.IntEnum):
    """Which signals ``rclpy.init`` handles (rclpy.signals.SignalHandlerOptions)."""

    NO = 0
    SIGINT = 1
    SIGTERM = 2
    ALL = 3


_previous: Any = None
_installed = False


def _on_sigint(signum: int, frame: Any) -> None:
    from .utilities import g_default_context

    if g_default_context is not None:
        g_default_context.try_shutdown()
    previous = _previous
    if callable(previous):
        previous(signum, frame)
    elif previous == signal.SIG_DFL:
        raise KeyboardInterrupt


def install_signal_handlers(options: SignalHandlerOptions | None = None) -> None:
    """Install the SIGINT handler (``options`` None means ALL, rclpy's default); only from the main thread, where
    Python allows it, and once."""
    global _previous, _installed
    options = SignalHandlerOptions.ALL if options is None else SignalHandlerOptions(options)
    if _installed or not options & SignalHandlerOptions.SIGINT:
        return
    if threading.current_thread() is not threading.main_thread():
        return
    _previous = signal.signal(signal.SIGINT, _on_sigint)
    _installed = True


def uninstall_signal_handlers() -> None:
    """Put the handler ``install_signal_handlers`` replaced back (if it is still ours)."""
    global _previous, _installed
    if not _installed:
        return
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is _on_sigint:
        signal.signal(signal.SIGINT, _previous if _previous is not None else signal.SIG_DFL)
    _previous, _installed = None, False
