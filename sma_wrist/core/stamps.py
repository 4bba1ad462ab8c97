"""Header stamps as the nodes read them (no ROS import: the sweep reads its ticks the same way)."""

from __future__ import annotations


def stamp_seconds(ns: int) -> float:
    """Time [s] of a header stamp of ``ns`` integer nanoseconds, read as ``sec + 1e-9 * nanosec`` -- what
    ``WristNode.stamp_s`` computes from a message. Not ``ns * 1e-9``, which differs in the last bits: the laws
    difference these times (dt, the TEM range refresh every 0.1 s), so whoever replays them must read them alike."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return sec + 1e-9 * nanosec
