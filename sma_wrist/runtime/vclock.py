"""The process-wide virtual clock that drives STEADY and SYSTEM time in the embedded runtime.

There is no wall clock anywhere in the runtime: ``steady_ns`` starts at 0 on ``rclpy.init()``
and only moves when the executor jumps it to the next timer deadline (or a test advances
it), so runs are as fast as the CPU allows and bit-for-bit repeatable.  SYSTEM time is
``system_epoch_ns + steady_ns`` (epoch 0 by default, so a graph whose /clock starts at 0
has sim time == virtual time).
"""

from __future__ import annotations


class VirtualClock:
    __slots__ = ('steady_ns', 'system_epoch_ns')

    def __init__(self) -> None:
        self.steady_ns = 0
        self.system_epoch_ns = 0

    def reset(self, system_epoch_ns: int = 0) -> None:
        self.steady_ns = 0
        self.system_epoch_ns = int(system_epoch_ns)

    @property
    def system_ns(self) -> int:
        return self.system_epoch_ns + self.steady_ns

    def advance_to(self, steady_ns: int) -> None:
        """Move steady time forward to steady_ns (never backwards)."""
        if steady_ns > self.steady_ns:
            self.steady_ns = steady_ns


VCLOCK = VirtualClock()
