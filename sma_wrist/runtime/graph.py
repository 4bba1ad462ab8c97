"""The in-process middleware: topics, matching, taps (recorders).

One ``Graph`` per rclpy Context.  Publishing copies the message once per matched
subscription (as a serialising middleware would give each reader its own object) into
that subscription's bounded queue; taps (bag recorders) see the original message and the
ROS time of the publishing node's clock.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from .errors import GraphError

Tap = Callable[['Topic', Any, int], None]


class Topic:
    __slots__ = ('name', 'msg_type', 'publishers', 'subscriptions', 'taps', '_cdr')

    def __init__(self, name: str, msg_type: type) -> None:
        self.name = name
        self.msg_type = msg_type
        self.publishers: list[Any] = []
        self.subscriptions: list[Any] = []
        self.taps: list[Tap] = []
        self._cdr: tuple[Any, bytes] | None = None  # the publication being dispatched to the taps, encoded

    def cdr(self, msg: Any, encode: Callable[[Any], bytes]) -> bytes:
        """``msg`` CDR-encoded once for all the taps of one publication (a bag recorder and the live view both
        need the bytes). Valid only while the publisher dispatches ``msg`` to the taps: it forgets the encoding
        before and after, so a node that publishes the same message object again after changing it is encoded
        again."""
        memo = self._cdr
        if memo is None or memo[0] is not msg:
            memo = self._cdr = (msg, bytes(encode(msg)))
        return memo[1]


class _TapEntry:
    __slots__ = ('fn', 'topics')

    def __init__(self, fn: Tap, topics: frozenset[str] | None) -> None:
        self.fn = fn
        self.topics = topics


class Graph:
    def __init__(self) -> None:
        self.topics: dict[str, Topic] = {}
        self.nodes: list[Any] = []
        self._taps: list[_TapEntry] = []
        self.version = 0  # bumped whenever entities are added/removed (executor caches)
        self.delivery: Any = None  # a runtime.delivery.DeliveryModel: latency/jitter; None = at once

    def topic(self, name: str, msg_type: type) -> Topic:
        t = self.topics.get(name)
        if t is None:
            t = Topic(name, msg_type)
            t.taps = [e.fn for e in self._taps if e.topics is None or name in e.topics]
            self.topics[name] = t
        elif t.msg_type is not msg_type:
            raise GraphError(
                f'topic {name!r} is used with two message types: '
                f'{getattr(t.msg_type, "_TYPE", t.msg_type)} and {getattr(msg_type, "_TYPE", msg_type)}'
            )
        return t

    def _rematch(self, topic: Topic) -> None:
        from .rclpy.qos import _compatible

        for pub in topic.publishers:
            pub._matched = [s for s in topic.subscriptions if _compatible(pub.qos_profile, s.qos_profile)]
        self.version += 1

    def add_publisher(self, pub: Any) -> None:
        topic = pub._topic
        topic.publishers.append(pub)
        self._rematch(topic)

    def add_subscription(self, sub: Any) -> None:
        from .rclpy.qos import _compatible

        topic = sub._topic
        topic.subscriptions.append(sub)
        self._rematch(topic)
        # TRANSIENT_LOCAL: a late-joining subscription receives each matched publisher's
        # stored history (oldest first).
        if sub.qos_profile._is_transient_local():
            for pub in topic.publishers:
                if pub._history is not None and _compatible(pub.qos_profile, sub.qos_profile):
                    for msg in pub._history:
                        sub._queue.append(msg._copy())

    def remove_publisher(self, pub: Any) -> None:
        topic = pub._topic
        if pub in topic.publishers:
            topic.publishers.remove(pub)
        self._rematch(topic)

    def remove_subscription(self, sub: Any) -> None:
        topic = sub._topic
        if sub in topic.subscriptions:
            topic.subscriptions.remove(sub)
        self._rematch(topic)

    def add_tap(self, fn: Tap, topics: Iterable[str] | None = None) -> Callable[[], None]:
        """Call fn(topic, msg, ros_time_ns) for every publication (on the given topics).

        Returns a function that removes the tap.
        """
        entry = _TapEntry(fn, frozenset(topics) if topics is not None else None)
        self._taps.append(entry)
        for t in self.topics.values():
            if entry.topics is None or t.name in entry.topics:
                t.taps.append(fn)

        def remove() -> None:
            if entry in self._taps:
                self._taps.remove(entry)
                for t in self.topics.values():
                    if fn in t.taps:
                        t.taps.remove(fn)

        return remove
