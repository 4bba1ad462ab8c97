"""Shared test set-up: the embedded rclpy runtime (before anything imports rclpy) and a
probe node that publishes inputs and collects outputs of a node under test."""
from __future__ import annotations

from typing import Any

import pytest

from sma_wrist import runtime

runtime.activate()


@pytest.fixture
def ros_shutdown():
    import rclpy
    yield
    rclpy.try_shutdown()


class Probe:
    """Publishes on and listens to contract topics, as a plain rclpy node."""

    def __init__(self, rt: Any, listen: tuple[str, ...] = (), name: str = 'probe', sim_time: bool = False) -> None:
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        from sma_wrist.contract import load_contract
        from sma_wrist.nodes.common import message_class, qos_for
        self.contract = load_contract()
        self.node = rt.add(Node(name, parameter_overrides=[Parameter('use_sim_time', value=sim_time)]))
        self.pubs: dict[str, Any] = {}
        self.got: dict[str, list[Any]] = {t: [] for t in listen + ('/diagnostics',)}
        for t in self.got:
            if t == '/diagnostics':
                from diagnostic_msgs.msg import DiagnosticArray
                self.node.create_subscription(DiagnosticArray, t, self.got[t].append, 10)
            else:
                c = self.contract.topic(t)
                self.node.create_subscription(message_class(c), t, self.got[t].append, qos_for(c))
        self._message_class = message_class
        self._qos_for = qos_for

    def publish(self, topic: str, **fields: Any) -> None:
        c = self.contract.topic(topic)
        if topic not in self.pubs:
            self.pubs[topic] = self.node.create_publisher(self._message_class(c), topic, self._qos_for(c))
        msg = self._message_class(c)(**fields)
        self.pubs[topic].publish(msg)

    def every(self, period_s: float, topic: str, **fields: Any) -> Any:
        """Publish the same message every period (a timer on the probe's clock)."""
        return self.node.create_timer(period_s, lambda: self.publish(topic, **fields))

    def diagnostics(self) -> list[tuple[str, int, str]]:
        return [(s.name, s.level[0] if isinstance(s.level, bytes) else int(s.level), s.message)
                for arr in self.got['/diagnostics'] for s in arr.status]


@pytest.fixture
def probe_factory():
    return Probe
