"""rclpy.subscription.Subscription with a KEEP_LAST/KEEP_ALL queue of its own."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from typing import Any

from .qos import QoSProfile


class Subscription:
    def __init__(
        self,
        node: Any,
        msg_type: type,
        topic: str,
        callback: Callable[[Any], None],
        callback_group: Any,
        qos_profile: QoSProfile,
        raw: bool,
        graph_topic: Any,
    ) -> None:
        self._node = node
        self.msg_type = msg_type
        self.topic = topic
        self.callback = callback
        self.callback_group = callback_group
        self.qos_profile = qos_profile
        self.raw = raw
        self._topic = graph_topic
        self._queue: deque[Any] = deque(maxlen=qos_profile._queue_len())

    @property
    def handle(self) -> Subscription:
        return self

    @property
    def topic_name(self) -> str:
        return self.topic

    def destroy(self) -> None:
        self._node.destroy_subscription(self)
