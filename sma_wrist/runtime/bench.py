"""Throughput of the embedded middleware: publish -> executor -> subscription callback.

Graph: a source node publishes ``std_msgs/Float64`` from a 1 kHz timer; a relay node
republishes every message on a second topic; a sink counts.  Each source tick therefore
costs one timer callback and two message deliveries.  Optionally a BagRecorder records
both topics (CDR serialisation + MCAP writing).
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any


def bench_messages(n: int = 20000, *, record: bool = False) -> dict[str, Any]:
    from . import activate
    if not activate():
        raise RuntimeError('bench_messages needs the embedded runtime (real rclpy is importable)')
    from .launch import Runtime
    from .messages import get_message_class
    from .rclpy.node import Node

    Float64 = get_message_class('std_msgs/msg/Float64')
    ticks = n // 2

    class Source(Node):
        def __init__(self) -> None:
            super().__init__('bench_source')
            self.pub = self.create_publisher(Float64, 'bench/a', 10)
            self.msg = Float64()
            self.create_timer(0.001, self.tick)

        def tick(self) -> None:
            self.msg.data += 1.0
            self.pub.publish(self.msg)

    class Relay(Node):
        def __init__(self) -> None:
            super().__init__('bench_relay')
            self.pub = self.create_publisher(Float64, 'bench/b', 10)
            self.create_subscription(Float64, 'bench/a', self.pub.publish, 10)

    class Sink(Node):
        def __init__(self) -> None:
            super().__init__('bench_sink')
            self.count = 0
            self.create_subscription(Float64, 'bench/b', self.cb, 10)

        def cb(self, msg: Any) -> None:
            self.count += 1

    with tempfile.TemporaryDirectory() as tmp, Runtime() as rt:
        if record:
            rt.record(Path(tmp) / 'bench_bag', ['bench/a', 'bench/b'])
        rt.add(Source)
        rt.add(Relay)
        sink = rt.add(Sink)
        t0 = time.perf_counter()
        result = rt.run_until(ticks * 0.001, until='steady')
        wall = time.perf_counter() - t0
        rt.close()
    delivered = sink.count * 2  # a and b deliveries
    return {
        'messages': delivered,
        'callbacks': result.callbacks,
        'wall_s': wall,
        'messages_per_s': delivered / wall,
        'us_per_message': wall / delivered * 1e6,
        'recorded': record,
    }
