"""Typed errors of the embedded runtime.

Each error says what was wrong and where, so a CLI can print it verbatim.
"""

from __future__ import annotations

from sma_wrist.core.errors import SmaWristError


class RuntimeErrorBase(SmaWristError):
    """Base class of every error raised on purpose by sma_wrist.runtime."""


class ActivationError(RuntimeErrorBase, RuntimeError):
    """The embedded rclpy could not be installed (e.g. the real rclpy is already imported)."""


class MessageTypeError(RuntimeErrorBase, TypeError):
    """A message type is unknown to the typestore, or a value does not fit its field."""


class ArgumentError(RuntimeErrorBase, ValueError):
    """A ROS command line argument (--ros-args ...) or a params file is malformed."""

    def __init__(self, what: str, where: str = '') -> None:
        self.what = what
        self.where = where
        super().__init__(f'{where}: {what}' if where else what)


class GraphError(RuntimeErrorBase, RuntimeError):
    """The node graph is inconsistent, e.g. one topic used with two message types."""
