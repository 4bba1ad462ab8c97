"""Timers with rcl_timer semantics (rcl/src/rcl/timer.c, Humble) on virtual time.

State is rcl's: ``last_call_time``, ``next_call_time`` (= init time + period), a
``time_credit`` for ROS time (de)activation, and ``canceled``.  ``_call`` is
``rcl_timer_call``: next_call advances by exactly one period, or by as many periods as
needed to pass ``now`` when calls were missed.  Timers on a ROS clock register rcl's jump
callback: a backward jump of more than one period restarts the period, and activating
``use_sim_time`` carries the elapsed part of the period into the new epoch.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .clock import Clock, ClockChange, ClockType, _JumpEntry


class Timer:
    def __init__(
        self,
        callback: Callable[[], Any] | None,
        callback_group: Any,
        timer_period_ns: int,
        clock: Clock,
        *,
        context: Any = None,
    ) -> None:
        period = int(timer_period_ns)
        if period < 0:
            raise ValueError('timer period must be non-negative')
        self._context = context
        self._clock = clock
        self.callback = callback
        self.callback_group = callback_group
        self._period = period
        now = clock._now_ns()
        self._last_call = now
        self._next_call = now + period
        self._credit = 0
        self._canceled = False
        self._destroyed = False
        self._jump: _JumpEntry | None = None
        if clock._clock_type is ClockType.ROS_TIME:
            self._jump = _JumpEntry(True, 1, -1, self._pre_jump, self._post_jump, self)
            clock._jump_entries.append(self._jump)

    # -- rcl jump callback -------------------------------------------------
    def _pre_jump(self, change: ClockChange, delta: int) -> None:
        if change in (ClockChange.ROS_TIME_ACTIVATED, ClockChange.ROS_TIME_DEACTIVATED):
            now = self._clock._now_ns()
            if now != 0:  # no time credit if the clock is uninitialised
                self._credit = self._next_call - now

    def _post_jump(self, change: ClockChange, delta: int) -> None:
        now = self._clock._now_ns()
        if change in (ClockChange.ROS_TIME_ACTIVATED, ClockChange.ROS_TIME_DEACTIVATED):
            if now == 0:
                return
            credit, self._credit = self._credit, 0
            if credit:
                self._next_call = now - credit + self._period
                self._last_call = now - credit
        elif self._next_call <= now:
            pass  # forward jump made the timer ready: the executor sees it on its next scan
        elif now < self._last_call:
            self._next_call = now + self._period
            self._last_call = now

    # -- public rclpy API --------------------------------------------------
    @property
    def handle(self) -> Timer:
        return self

    @property
    def clock(self) -> Clock:
        return self._clock

    @property
    def timer_period_ns(self) -> int:
        return self._period

    @timer_period_ns.setter
    def timer_period_ns(self, value: int) -> None:
        self._period = int(value)

    def is_ready(self) -> bool:
        return not self._canceled and self._clock._now_ns() >= self._next_call

    def is_canceled(self) -> bool:
        return self._canceled

    def cancel(self) -> None:
        self._canceled = True

    def reset(self) -> None:
        now = self._clock._now_ns()
        self._next_call = now + self._period
        self._canceled = False

    def time_since_last_call(self) -> int:
        return self._clock._now_ns() - self._last_call

    def time_until_next_call(self) -> int | None:
        if self._canceled:
            return None
        return self._next_call - self._clock._now_ns()

    def destroy(self) -> None:
        self._canceled = True
        self._destroyed = True
        if self._jump is not None and self._jump in self._clock._jump_entries:
            self._clock._jump_entries.remove(self._jump)
            self._jump = None

    # -- executor side -----------------------------------------------------
    def _call(self) -> bool:
        """rcl_timer_call: update call times; False if canceled."""
        if self._canceled:
            return False
        now = self._clock._now_ns()
        self._last_call = now
        period = self._period
        nxt = self._next_call + period
        if nxt < now:
            if period == 0:
                nxt = now
            else:
                ahead = now - nxt
                nxt += (1 + (ahead - 1) // period) * period
        self._next_call = nxt
        return True
