"""rclpy.publisher.Publisher on the in-process graph."""

from __future__ import annotations

from collections import deque
from typing import Any

from ..vclock import VCLOCK
from .exceptions import RCLError
from .qos import QoSProfile


class Publisher:
    def __init__(self, node: Any, msg_type: type, topic: str, qos_profile: QoSProfile, graph_topic: Any) -> None:
        self._node = node
        self.msg_type = msg_type
        self.topic = topic
        self.qos_profile = qos_profile
        self._topic = graph_topic
        self._matched: list[Any] = []
        # TRANSIENT_LOCAL publishers keep their last `depth` messages for late joiners.
        self._history: deque[Any] | None = (
            deque(maxlen=qos_profile._queue_len()) if qos_profile._is_transient_local() else None
        )
        self._clock = node._clock
        self._graph = node._context.graph
        self._destroyed = False

    @property
    def handle(self) -> Publisher:
        return self

    @property
    def topic_name(self) -> str:
        return self.topic

    def publish(self, msg: Any) -> None:
        if type(msg) is not self.msg_type:
            raise TypeError(f'Expected {self.msg_type}, got {type(msg)}')
        if self._destroyed:
            raise RuntimeError('cannot publish on a destroyed publisher')
        if not self._node._context.ok():
            # as rclpy's rcl_publish: after shutdown (Ctrl-C under ros2 run) a publication raises, so a node that
            # publishes while being torn down fails here as it does under ROS 2
            raise RCLError("publisher's context is invalid")
        topic = self._topic
        if topic.taps:
            t = self._clock._now_ns()
            topic._cdr = None
            for tap in topic.taps:
                tap(topic, msg, t)
            topic._cdr = None
        delivery = self._graph.delivery
        if delivery is None:
            for sub in self._matched:
                sub._queue.append(msg._copy())
        else:
            now = VCLOCK.steady_ns
            for sub in self._matched:
                delivery.send(self, sub, msg._copy(), now)
        if self._history is not None:
            self._history.append(msg._copy())

    def get_subscription_count(self) -> int:
        return len(self._matched)

    def assert_liveliness(self) -> None:
        pass

    def wait_for_all_acked(self, timeout: Any = None) -> bool:
        return True

    def destroy(self) -> None:
        self._node.destroy_publisher(self)
