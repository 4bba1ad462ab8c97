"""rclpy.duration.Duration (semantics of rclpy/duration.py, Humble), pure Python."""

from __future__ import annotations

from typing import Any

from sma_wrist.runtime.messages import get_message_class

from .constants import S_TO_NS


class Duration:
    """A period between two time points, with nanosecond precision."""

    __slots__ = ('_ns',)

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        total = int(seconds * S_TO_NS) + int(nanoseconds)
        if total >= 2**63 or total < -(2**63):
            raise OverflowError('Total nanoseconds value is too large to store in C duration.')
        self._ns = total

    @property
    def nanoseconds(self) -> int:
        return self._ns

    def __repr__(self) -> str:
        return f'Duration(nanoseconds={self._ns})'

    def __str__(self) -> str:
        if self._ns == Infinite._ns:
            return 'Infinite'
        return f'{self._ns} nanoseconds'

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Duration):
            return self._ns == other._ns
        raise TypeError("Can't compare duration with object of type: ", type(other))

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    def __hash__(self) -> int:
        return hash(self._ns)

    def __lt__(self, other: Any) -> bool:
        if isinstance(other, Duration):
            return self._ns < other._ns
        return NotImplemented

    def __le__(self, other: Any) -> bool:
        if isinstance(other, Duration):
            return self._ns <= other._ns
        return NotImplemented

    def __gt__(self, other: Any) -> bool:
        if isinstance(other, Duration):
            return self._ns > other._ns
        return NotImplemented

    def __ge__(self, other: Any) -> bool:
        if isinstance(other, Duration):
            return self._ns >= other._ns
        return NotImplemented

    def to_msg(self) -> Any:
        sec, nsec = divmod(self._ns, S_TO_NS)
        return get_message_class('builtin_interfaces/msg/Duration')(sec=sec, nanosec=nsec)

    @classmethod
    def from_msg(cls, msg: Any) -> Duration:
        if type(msg) is not get_message_class('builtin_interfaces/msg/Duration'):
            raise TypeError('Must pass a builtin_interfaces.msg.Duration object')
        return cls(seconds=msg.sec, nanoseconds=msg.nanosec)


Infinite = Duration(nanoseconds=2**63 - 1)
