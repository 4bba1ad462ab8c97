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


#: what makes each node of the closed loop compute, as the real nodes do: a timer (None) or
#: the last input of a tick to arrive (the plant publishes muscle 2 after muscle 1)
FLOOR_TRIGGERS: dict[str, str | None] = {
    'plant_sim': None,
    'trajectory_generator': None,
    'adaptive_controller': '/wrist/joint_states',
    'hysteresis_compensator': '/wrist/muscle_2/stress_desired',
    'tem_controller': '/wrist/muscle_2/temperature',
}


def bench_contract_floor(duration_s: float = 20.0, rate_hz: float = 100.0) -> dict[str, Any]:
    """Real-time factor of the closed loop's topology with nodes that do no work.

    One node per publisher of the contract (msg_defs/topics.yaml), subscribed to what the
    contract says it reads and publishing every periodic topic it owns once per tick, with
    the stamps and frame ids the real nodes write; /clock drives the others' sim time as in
    the closed loop. What this reaches is the ceiling for any node implementation on this
    runtime: messages, deliveries, timers and sim time only, no numerics, no checks.
    """
    from . import activate

    if not activate():
        raise RuntimeError('bench_contract_floor needs the embedded runtime (real rclpy is importable)')
    from sma_wrist.contract import load_contract
    from sma_wrist.nodes.common import message_class, qos_for

    from .launch import Runtime
    from .rclpy.node import Node
    from .rclpy.parameter import Parameter

    contract = load_contract()
    # the simulated loop's topology: a topic only the hardware bridge publishes is not in it ('*': every node's)
    periodic = [t for t in contract.topics.values() if t.rate_hz > 0 and t.publisher in (*FLOOR_TRIGGERS, '*')]
    period = 1.0 / rate_hz

    class Skeleton(Node):
        """Publishes its periodic topics, filled with constants, on its trigger."""

        def __init__(self, name: str) -> None:
            super().__init__(name, parameter_overrides=[Parameter('use_sim_time', value=name != 'plant_sim')])
            self.outputs = [
                (self.create_publisher(message_class(t), t.name, qos_for(t)), message_class(t), t)
                for t in periodic
                if t.publisher == name
            ]
            trigger = FLOOR_TRIGGERS[name]
            for t in periodic:
                if name in t.subscribers and t.name != '/clock':
                    cb = self.tick if t.name == trigger else self.take
                    self.create_subscription(message_class(t), t.name, cb, qos_for(t))
            if trigger is None:
                self.create_timer(period, self.tick)
            self.latest: Any = None

        def take(self, msg: Any) -> None:
            self.latest = msg

        def tick(self, msg: Any = None) -> None:
            stamp = self.get_clock().now().to_msg()
            for pub, cls, t in self.outputs:
                m = cls()
                if t.type == 'rosgraph_msgs/msg/Clock':
                    m.clock = stamp
                elif t.type == 'std_msgs/msg/Float64':
                    m.data = 1.0
                else:
                    m.header.stamp = stamp
                    m.header.frame_id = contract.frame_id
                    if t.type == 'sensor_msgs/msg/Temperature':
                        m.temperature = 40.0
                    else:  # JointState
                        m.name, m.position, m.velocity, m.effort = [contract.joint_name], [0.5], [0.0], [0.0]
                pub.publish(m)

    with Runtime() as rt:
        for name in FLOOR_TRIGGERS:
            rt.add(Skeleton, name)
        t0 = time.perf_counter()
        result = rt.run_until(duration_s, until='steady')
        wall = time.perf_counter() - t0
        rt.close()
    ticks = duration_s * rate_hz
    return {
        'sim_time_s': duration_s,
        'real_time_factor': duration_s / wall,
        'us_per_tick': wall / ticks * 1e6,
        'published_per_tick': len(periodic),
        'deliveries_per_tick': sum(len(t.subscribers) for t in periodic),
        'callbacks_per_tick': result.callbacks / ticks,
    }
