"""Clocks on virtual time (semantics of rclpy/clock.py and rcl/time.c, Humble).

SYSTEM_TIME and STEADY_TIME read the process-wide virtual clock
(:mod:`sma_wrist.runtime.vclock`).  ROS_TIME reads SYSTEM time unless a TimeSource has
activated the ROS time override (``use_sim_time``), in which case it returns the last
override value (set from /clock).  Jump callbacks follow rcl: on override change while
active, callbacks whose threshold is exceeded get pre/post calls; activating or
deactivating the override is a clock change.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sma_wrist.runtime.vclock import VCLOCK

from .clock_type import ClockChange, ClockType
from .duration import Duration
from .exceptions import NotInitializedException
from .time import Time

__all__ = ['Clock', 'ClockChange', 'ClockType', 'JumpHandle', 'JumpThreshold', 'ROSClock', 'TimeJump']


class JumpThreshold:
    def __init__(
        self, *, min_forward: Duration | None, min_backward: Duration | None, on_clock_change: bool = True
    ) -> None:
        if min_forward is not None and min_forward.nanoseconds <= 0:
            raise ValueError('min_forward must be a positive non-zero duration')
        if min_backward is not None and min_backward.nanoseconds >= 0:
            raise ValueError('min_backward must be a negative non-zero duration')
        if min_forward is None and min_backward is None and not on_clock_change:
            raise ValueError('At least one jump threshold must be enabled')
        self.min_forward = min_forward
        self.min_backward = min_backward
        self.on_clock_change = on_clock_change


class TimeJump:
    def __init__(self, clock_change: ClockChange, delta: Duration) -> None:
        if not isinstance(clock_change, ClockChange):
            raise TypeError('clock_change must be an instance of rclpy.clock.ClockChange')
        self._clock_change = clock_change
        self._delta = delta

    @property
    def clock_change(self) -> ClockChange:
        return self._clock_change

    @property
    def delta(self) -> Duration:
        return self._delta


class _JumpEntry:
    """One registered jump callback in rcl terms: raw ns thresholds and raw callbacks."""

    __slots__ = ('on_clock_change', 'min_forward', 'min_backward', 'pre', 'post', 'owner')

    def __init__(
        self,
        on_clock_change: bool,
        min_forward: int,
        min_backward: int,
        pre: Callable[[ClockChange, int], None] | None,
        post: Callable[[ClockChange, int], None] | None,
        owner: object,
    ) -> None:
        self.on_clock_change = on_clock_change
        self.min_forward = min_forward
        self.min_backward = min_backward
        self.pre = pre
        self.post = post
        self.owner = owner

    def triggers(self, change: ClockChange, delta: int) -> bool:
        is_change = change in (ClockChange.ROS_TIME_ACTIVATED, ClockChange.ROS_TIME_DEACTIVATED)
        return (
            (is_change and self.on_clock_change)
            or (self.min_forward > 0 and delta >= self.min_forward)
            or (self.min_backward < 0 and delta <= self.min_backward)
        )


class JumpHandle:
    def __init__(
        self,
        *,
        clock: Clock,
        threshold: JumpThreshold,
        pre_callback: Callable[[], None] | None,
        post_callback: Callable[[TimeJump], None] | None,
    ) -> None:
        if pre_callback is None and post_callback is None:
            raise ValueError('One of pre_callback or post_callback must be callable')
        if pre_callback is not None and not callable(pre_callback):
            raise ValueError('pre_callback must be callable if given')
        if post_callback is not None and not callable(post_callback):
            raise ValueError('post_callback must be callable if given')
        self._clock: Clock | None = clock
        pre = None
        if pre_callback is not None:

            def pre(change: ClockChange, delta: int) -> None:
                pre_callback()

        post = None
        if post_callback is not None:

            def post(change: ClockChange, delta: int) -> None:
                post_callback(TimeJump(change, Duration(nanoseconds=delta)))

        self._entry = _JumpEntry(
            threshold.on_clock_change,
            threshold.min_forward.nanoseconds if threshold.min_forward is not None else 0,
            threshold.min_backward.nanoseconds if threshold.min_backward is not None else 0,
            pre,
            post,
            self,
        )
        clock._jump_entries.append(self._entry)

    def unregister(self) -> None:
        if self._clock is not None:
            self._clock._jump_entries.remove(self._entry)
            self._clock = None

    def __enter__(self) -> JumpHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.unregister()


class Clock:
    __slots__ = ('_clock_type', '_jump_entries', '_ros_active', '_override_ns', '__weakref__')

    def __new__(cls, *, clock_type: ClockType = ClockType.SYSTEM_TIME) -> Clock:
        if not isinstance(clock_type, ClockType):
            raise TypeError('Clock type must be a ClockType enum')
        self = super().__new__(ROSClock if clock_type is ClockType.ROS_TIME else cls)
        self._clock_type = clock_type
        self._jump_entries: list[_JumpEntry] = []
        self._ros_active = False
        self._override_ns = 0
        return self

    @property
    def clock_type(self) -> ClockType:
        return self._clock_type

    @property
    def handle(self) -> Clock:
        return self

    def __repr__(self) -> str:
        return f'Clock(clock_type={self._clock_type.name})'

    def _now_ns(self) -> int:
        if self._clock_type is ClockType.STEADY_TIME:
            return VCLOCK.steady_ns
        if self._ros_active:
            return self._override_ns
        return VCLOCK.system_epoch_ns + VCLOCK.steady_ns

    def _follows_virtual_clock(self) -> bool:
        """True if time on this clock advances with the virtual steady clock."""
        return not self._ros_active

    def _virtual_offset_ns(self) -> int:
        """this clock's now minus virtual steady now (valid if _follows_virtual_clock())."""
        return 0 if self._clock_type is ClockType.STEADY_TIME else VCLOCK.system_epoch_ns

    def now(self) -> Time:
        return Time._from_ns(self._now_ns(), self._clock_type)

    def create_jump_callback(
        self,
        threshold: JumpThreshold,
        *,
        pre_callback: Callable[[], None] | None = None,
        post_callback: Callable[[TimeJump], None] | None = None,
    ) -> JumpHandle:
        return JumpHandle(clock=self, threshold=threshold, pre_callback=pre_callback, post_callback=post_callback)

    def _call_jump(self, change: ClockChange, delta: int, before: bool) -> None:
        for entry in list(self._jump_entries):
            if entry.triggers(change, delta):
                if before and entry.pre is not None:
                    entry.pre(change, delta)
                elif not before and entry.post is not None:
                    entry.post(change, delta)

    def sleep_until(self, until: Time, context: Any = None) -> bool:
        """Advance virtual time to ``until`` (SYSTEM/STEADY); see doc/explanation/runtime.md.

        There is nothing to wait for in a single-threaded virtual-time process, so sleeping
        on a clock that follows the virtual clock moves the virtual clock; sleeping on an
        overridden ROS clock cannot make /clock advance and raises RuntimeError.
        """
        from .utilities import get_default_context

        ctx = context if context is not None else get_default_context()
        if not ctx.ok():
            raise NotInitializedException()
        if until.clock_type != self._clock_type:
            raise ValueError("until's clock type does not match this clock's type")
        if not self._follows_virtual_clock():
            if self._now_ns() >= until.nanoseconds:
                return True
            raise RuntimeError(
                'sleep on a ROS clock driven by /clock would never return in the single-threaded embedded runtime'
            )
        VCLOCK.advance_to(until.nanoseconds - self._virtual_offset_ns())
        return True

    def sleep_for(self, rel_time: Duration, context: Any = None) -> bool:
        return self.sleep_until(self.now() + rel_time, context)


class ROSClock(Clock):
    __slots__ = ()

    def __new__(cls) -> ROSClock:
        return super().__new__(Clock, clock_type=ClockType.ROS_TIME)  # type: ignore[return-value]

    @property
    def ros_time_is_active(self) -> bool:
        return self._ros_active

    def _set_ros_time_is_active(self, enabled: bool) -> None:
        enabled = bool(enabled)
        if enabled == self._ros_active:
            return
        change = ClockChange.ROS_TIME_ACTIVATED if enabled else ClockChange.ROS_TIME_DEACTIVATED
        self._call_jump(change, 0, True)
        self._ros_active = enabled
        self._call_jump(change, 0, False)

    def set_ros_time_override(self, time: Time) -> None:
        if not isinstance(time, Time):
            raise TypeError(f'Time must be specified as rclpy.time.Time. Received type: {type(time)}')
        self._set_override_ns(time.nanoseconds)

    def _set_override_ns(self, ns: int) -> None:
        if self._ros_active and self._jump_entries:
            delta = ns - self._override_ns
            self._call_jump(ClockChange.ROS_TIME_NO_CHANGE, delta, True)
            self._override_ns = ns
            self._call_jump(ClockChange.ROS_TIME_NO_CHANGE, delta, False)
        else:
            self._override_ns = ns
