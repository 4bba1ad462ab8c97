"""rclpy.time.Time (semantics of rclpy/time.py, Humble), pure Python."""

from __future__ import annotations

from typing import Any

from sma_wrist.runtime.messages import get_message_class

from .clock_type import ClockType
from .duration import Duration

CONVERSION_CONSTANT = 10**9


class Time:
    __slots__ = ('_ns', '_clock_type')

    def __init__(
        self, *, seconds: float = 0, nanoseconds: int = 0, clock_type: ClockType = ClockType.SYSTEM_TIME
    ) -> None:
        if not isinstance(clock_type, ClockType):
            raise TypeError('Clock type must be a ClockType enum')
        if seconds < 0:
            raise ValueError('Seconds value must not be negative')
        if nanoseconds < 0:
            raise ValueError('Nanoseconds value must not be negative')
        total = int(seconds * CONVERSION_CONSTANT) + int(nanoseconds)
        if total >= 2**63:
            raise OverflowError('Total nanoseconds value is too large to store in C time point.')
        self._ns = total
        self._clock_type = clock_type

    @classmethod
    def _from_ns(cls, ns: int, clock_type: ClockType) -> Time:
        t = object.__new__(cls)
        t._ns = ns
        t._clock_type = clock_type
        return t

    @property
    def nanoseconds(self) -> int:
        return self._ns

    def seconds_nanoseconds(self) -> tuple[int, int]:
        return (self._ns // CONVERSION_CONSTANT, self._ns % CONVERSION_CONSTANT)

    @property
    def clock_type(self) -> ClockType:
        return self._clock_type

    def __repr__(self) -> str:
        return f'Time(nanoseconds={self._ns}, clock_type={self._clock_type.name})'

    def __add__(self, other: Any) -> Time:
        if isinstance(other, Duration):
            try:
                return Time(nanoseconds=self._ns + other.nanoseconds, clock_type=self._clock_type)
            except OverflowError as e:
                raise OverflowError('Addition leads to overflow in C storage.') from e
        return NotImplemented

    def __radd__(self, other: Any) -> Time:
        return self.__add__(other)

    def __sub__(self, other: Any) -> Any:
        if isinstance(other, Time):
            if self._clock_type != other._clock_type:
                raise TypeError("Can't subtract times with different clock types")
            return Duration(nanoseconds=self._ns - other._ns)
        if isinstance(other, Duration):
            try:
                return Time(nanoseconds=self._ns - other.nanoseconds, clock_type=self._clock_type)
            except ValueError as e:
                raise ValueError('Subtraction leads to negative time.') from e
        return NotImplemented

    def _check(self, other: Time) -> None:
        if self._clock_type != other._clock_type:
            raise TypeError("Can't compare times with different clock types")

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Time):
            self._check(other)
            return self._ns == other._ns
        raise TypeError("Can't compare time with object of type: ", type(other))

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    def __hash__(self) -> int:
        return hash((self._ns, self._clock_type))

    def __lt__(self, other: Any) -> bool:
        if isinstance(other, Time):
            self._check(other)
            return self._ns < other._ns
        return NotImplemented

    def __le__(self, other: Any) -> bool:
        if isinstance(other, Time):
            self._check(other)
            return self._ns <= other._ns
        return NotImplemented

    def __gt__(self, other: Any) -> bool:
        if isinstance(other, Time):
            self._check(other)
            return self._ns > other._ns
        return NotImplemented

    def __ge__(self, other: Any) -> bool:
        if isinstance(other, Time):
            self._check(other)
            return self._ns >= other._ns
        return NotImplemented

    def to_msg(self) -> Any:
        sec, nsec = divmod(self._ns, CONVERSION_CONSTANT)
        return get_message_class('builtin_interfaces/msg/Time')(sec=sec, nanosec=nsec)

    @classmethod
    def from_msg(cls, msg: Any, clock_type: ClockType = ClockType.ROS_TIME) -> Time:
        if type(msg) is not get_message_class('builtin_interfaces/msg/Time'):
            raise TypeError('Must pass a builtin_interfaces.msg.Time object')
        return cls(seconds=msg.sec, nanoseconds=msg.nanosec, clock_type=clock_type)
