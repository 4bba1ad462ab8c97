"""Optional message delivery model of the embedded middleware: latency and jitter per topic.

By default the embedded runtime delivers a message to every matched subscription at the
instant it is published, in a fixed order: deterministic and bit-reproducible. Real
middleware (DDS through rclpy, even on one host) hands a message over after a latency that
varies from message to message, so two messages published in one order on two topics can
be taken in the other. With a :class:`DeliveryModel` on the graph every (publication,
subscription) pair gets ``latency + Exp(jitter)`` of virtual steady time, drawn from a seeded
generator (the same seed gives the same run); messages of one publisher to one subscription
keep their order, as a RELIABLE DDS writer/reader pair does. Only the timing changes: no
message is dropped here (a subscription's KEEP_LAST depth still applies when it is taken).
"""

from __future__ import annotations

import heapq
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class DeliveryModel:
    """Latency [s] plus exponentially distributed jitter [s] (mean) of every delivery.

    ``per_topic`` maps a topic name to its own ``(latency_s, jitter_s)``. Defaults: what rclpy
    on Cyclone DDS shows on one loaded host for small messages, a few hundred microseconds with
    a tail into milliseconds.
    """

    latency_s: float = 3e-4
    jitter_s: float = 1e-3
    per_topic: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    seed: int = 0

    def __post_init__(self) -> None:
        for name, (lat, jit) in [('*', (self.latency_s, self.jitter_s)), *self.per_topic.items()]:
            if not (lat >= 0.0 and jit >= 0.0):
                raise ValueError(f'delivery model for {name}: latency and jitter must be >= 0, got {lat}, {jit}')
        self._rng = np.random.default_rng(self.seed)
        self._in_flight: list[tuple[int, int, Any, Any]] = []  # (due ns, order, subscription, message)
        self._order = 0
        self._last_due: dict[tuple[int, int], int] = {}  # (id(publisher), id(subscription)) -> due ns

    def send(self, publisher: Any, subscription: Any, msg: Any, now_ns: int) -> None:
        lat, jit = self.per_topic.get(publisher.topic, (self.latency_s, self.jitter_s))
        delay = lat + (self._rng.exponential(jit) if jit > 0 else 0.0)
        key = (id(publisher), id(subscription))
        due = max(now_ns + int(round(delay * 1e9)), self._last_due.get(key, 0))  # in order per writer/reader
        self._last_due[key] = due
        self._order += 1
        heapq.heappush(self._in_flight, (due, self._order, subscription, msg))

    def deliver_due(self, now_ns: int) -> None:
        """Hand every message due by ``now_ns`` to its subscription's queue."""
        q = self._in_flight
        while q and q[0][0] <= now_ns:
            _, _, sub, msg = heapq.heappop(q)
            if sub in sub._topic.subscriptions:  # not destroyed meanwhile
                sub._queue.append(msg)

    def next_due_ns(self) -> int | None:
        return self._in_flight[0][0] if self._in_flight else None


__all__ = ['DeliveryModel']
