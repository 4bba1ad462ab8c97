"""Timers, virtual/sim time, QoS depth and determinism of the embedded executor."""

from __future__ import annotations

import pytest

from sma_wrist import runtime

runtime.activate()

import rclpy  # noqa: E402
from rclpy.clock import Clock, ClockType  # noqa: E402
from rclpy.duration import Duration  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data  # noqa: E402
from rclpy.time import Time  # noqa: E402
from rosgraph_msgs.msg import Clock as ClockMsg  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

from sma_wrist.runtime.launch import Runtime  # noqa: E402


@pytest.fixture(autouse=True)
def _shutdown():
    yield
    rclpy.try_shutdown()


class Ticker(Node):
    def __init__(self, name='ticker', period=0.01, **kw):
        super().__init__(name, **kw)
        self.stamps = []
        self.timer = self.create_timer(period, self.tick)

    def tick(self):
        self.stamps.append(self.get_clock().now().nanoseconds)


class ClockPub(Node):
    """Publishes /clock = sim time advancing 10 ms per 10 ms of virtual time."""

    def __init__(self, stop_after=None):
        super().__init__('clock_pub')
        self.pub = self.create_publisher(ClockMsg, '/clock', 10)
        self.t = 0
        self.stop_after = stop_after
        self.create_timer(0.01, self.tick)

    def tick(self):
        if self.stop_after is not None and self.t >= self.stop_after:
            return
        self.t += 10_000_000
        m = ClockMsg()
        m.clock = Time(nanoseconds=self.t).to_msg()
        self.pub.publish(m)


def test_wall_timer_runs_on_virtual_time():
    with Runtime() as rt:
        n = rt.add(Ticker)
        res = rt.run_until(1.0)
        assert res.reason == 'time'
        assert len(n.stamps) == 100
        assert n.stamps[0] == 10_000_000 and n.stamps[-1] == 1_000_000_000
        assert res.wall_s < 1.0  # faster than real time


def test_sim_time_node_ticks_only_when_clock_advances():
    with Runtime(params={'/sim': {'use_sim_time': True}}) as rt:
        sim = rt.add(Ticker, 'sim')
        assert sim.get_clock().ros_time_is_active
        rt.run_until(0.5, until='steady')
        assert sim.stamps == []  # no /clock yet: ROS time stays at 0
        rt.add(ClockPub, stop_after=300_000_000)
        rt.run_until(2.0, until='steady')
        # ticks exactly at each new /clock value up to 0.3 s, then time stands still
        assert sim.stamps == [i * 10_000_000 for i in range(1, 31)]


def test_sim_time_run_until_stops_on_clock():
    with Runtime(params={'/sim': {'use_sim_time': True}}) as rt:
        rt.add(ClockPub)
        sim = rt.add(Ticker, 'sim', period=0.1)
        res = rt.run_until(1.0)  # auto -> sim time
        assert res.sim_ns == 1_000_000_000
        assert sim.stamps[-1] == 1_000_000_000  # work due at the end instant is done
        assert len(sim.stamps) == 10


def test_enabling_use_sim_time_later_switches_clock():
    with Runtime() as rt:
        n = rt.add(Ticker, 'late')
        rt.add(ClockPub)
        rt.run_until(0.05, until='steady')
        assert n.get_clock().now().clock_type == ClockType.ROS_TIME
        n.set_parameters([Parameter('use_sim_time', value=True)])
        assert n.get_clock().ros_time_is_active
        assert n.get_clock().now().nanoseconds == 0  # no /clock received yet by this node
        rt.run_until(0.2, until='steady')
        assert n.get_clock().now().nanoseconds == 200_000_000


def test_backward_jump_restarts_period():
    rclpy.init()
    n = Ticker('b', period=0.1, parameter_overrides=[Parameter('use_sim_time', value=True)])
    clock = n.get_clock()
    clock.set_ros_time_override(Time(seconds=5, clock_type=ClockType.ROS_TIME))
    assert n.timer.is_ready()
    ex = SingleThreadedExecutor()
    ex.add_node(n)
    ex.spin_once(timeout_sec=0)
    assert n.stamps == [5_000_000_000]
    clock.set_ros_time_override(Time(seconds=1, clock_type=ClockType.ROS_TIME))
    assert n.timer.time_until_next_call() == 100_000_000


def test_missed_periods_fire_once_then_realign():
    rclpy.init()
    n = Ticker('m', period=0.1, parameter_overrides=[Parameter('use_sim_time', value=True)])
    ex = SingleThreadedExecutor()
    ex.add_node(n)
    n.get_clock().set_ros_time_override(Time(nanoseconds=350_000_000, clock_type=ClockType.ROS_TIME))
    ex.run_until(0)
    assert n.stamps == [350_000_000]
    assert n.timer.time_until_next_call() == 50_000_000  # next at 0.4 s, as rcl_timer_call


def test_clocks_and_time_api():
    rclpy.init()
    steady = Clock(clock_type=ClockType.STEADY_TIME)
    assert steady.now().nanoseconds == 0
    t = Time(seconds=1.5, clock_type=ClockType.ROS_TIME)
    assert t.seconds_nanoseconds() == (1, 500_000_000)
    assert (t + Duration(seconds=0.5)).nanoseconds == 2_000_000_000
    assert Time.from_msg(t.to_msg()) == t
    with pytest.raises(TypeError):
        _ = t == Time(seconds=1.5)  # different clock types
    steady.sleep_for(Duration(seconds=2))
    assert steady.now().nanoseconds == 2_000_000_000


class Burst(Node):
    def __init__(self):
        super().__init__('burst')
        self.pub = self.create_publisher(Float64, 'x', 10)
        self.create_timer(0.1, self.tick)

    def tick(self):
        for i in range(7):
            self.pub.publish(Float64(data=float(i)))


class Sink(Node):
    def __init__(self, name, qos):
        super().__init__(name)
        self.got = []
        self.create_subscription(Float64, 'x', lambda m: self.got.append(m.data), qos)


def test_keep_last_depth_per_subscription_and_qos_matching():
    with Runtime() as rt:
        burst = rt.add(Burst)
        a = rt.add(Sink, 'a', 3)
        b = rt.add(Sink, 'b', qos_profile_sensor_data)  # depth 5, best effort
        c = rt.add(Sink, 'c', QoSProfile(depth=100))
        rt.run_until(0.1)
        assert a.got == [4.0, 5.0, 6.0]
        assert b.got == [2.0, 3.0, 4.0, 5.0, 6.0]
        assert c.got == [float(i) for i in range(7)]
        assert burst.pub.get_subscription_count() == 3
    with Runtime() as rt:
        be = rt.add(Node, 'be')
        pub = be.create_publisher(Float64, 'y', QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        rel = rt.add(Sink, 'rel', 10)
        rel.create_subscription(Float64, 'y', rel.got.append, 10)  # RELIABLE: not matched
        assert pub.get_subscription_count() == 0


def test_subscriber_gets_a_copy():
    with Runtime() as rt:
        src = rt.add(Node, 'src')
        pub = src.create_publisher(Float64, 'x', 10)
        sink = rt.add(Sink, 's', 10)
        m = Float64(data=1.0)
        pub.publish(m)
        m.data = 2.0
        pub.publish(m)
        rt.run_until(0)
        assert sink.got == [1.0, 2.0]


def _pingpong_trace():
    trace = []
    with Runtime() as rt:

        class A(Node):
            def __init__(self):
                super().__init__('a')
                self.pub = self.create_publisher(Float64, 'ping', 10)
                self.create_subscription(Float64, 'pong', lambda m: trace.append(('a', m.data)), 10)
                self.create_timer(0.003, lambda: self.pub.publish(Float64(data=float(len(trace)))))

        class B(Node):
            def __init__(self):
                super().__init__('b')
                self.pub = self.create_publisher(Float64, 'pong', 10)
                self.create_subscription(Float64, 'ping', self.cb, 10)
                self.create_timer(0.007, lambda: trace.append(('b-timer', self.get_clock().now().nanoseconds)))

            def cb(self, m):
                trace.append(('b', m.data))
                self.pub.publish(Float64(data=m.data * 2))

        rt.add(A)
        rt.add(B)
        rt.run_until(0.1)
    return trace


def test_same_inputs_same_callback_order():
    t1 = _pingpong_trace()
    t2 = _pingpong_trace()
    assert t1 == t2 and len(t1) > 50


def test_stop_condition_and_spin_once():
    with Runtime() as rt:
        n = rt.add(Ticker)
        res = rt.run_until(10.0, stop_when=lambda: len(n.stamps) >= 5)
        assert res.reason == 'condition' and len(n.stamps) == 5
        rclpy.spin_once(n, executor=rt.executor, timeout_sec=0.001)
        assert len(n.stamps) == 5  # timeout shorter than the period: only time moved
        rclpy.spin_once(n, executor=rt.executor)
        assert len(n.stamps) == 6


def test_logger_filters():
    from rclpy import logging as rlog

    rclpy.init()
    records = []
    remove = rlog.add_sink(lambda sev, name, msg, t: records.append(msg))
    old, rlog.stream_output = rlog.stream_output, False
    try:
        n = Node('log')
        for i in range(5):
            n.get_logger().info(f'once {i}', once=True)
            n.get_logger().warning(f'skip {i}', skip_first=True)
            n.get_logger().error(f'thr {i}', throttle_duration_sec=1.0)
            Clock(clock_type=ClockType.STEADY_TIME).sleep_for(Duration(seconds=0.4))
        n.get_logger().debug('hidden')
    finally:
        remove()
        rlog.stream_output = old
    assert records.count('once 0') == 1 and not any(r.startswith('once 1') for r in records)
    assert 'skip 0' not in records and 'skip 4' in records
    assert [r for r in records if r.startswith('thr')] == ['thr 0', 'thr 3']
    assert 'hidden' not in records


def test_force_activation_refused_when_real_rclpy_imported(monkeypatch):
    import sys
    import types

    from sma_wrist.runtime.errors import ActivationError

    fake = types.ModuleType('rclpy')
    monkeypatch.setattr(runtime, '_finder', None)
    monkeypatch.setitem(sys.modules, 'rclpy', fake)
    with pytest.raises(ActivationError, match='already imported'):
        runtime.activate(force=True)
    assert runtime.activate() is False


def test_silenced_keeps_records_off_stderr_and_restores_the_stream(capsys):
    """The project's tools that build nodes only for their parameters or their speed (sweep --params-file, the
    sweep benchmark) print none of the nodes' lines; sinks (the bag's /rosout) still get them, and the stream comes
    back as it was, also after an error inside."""
    from sma_wrist.runtime.rclpy import logging as rlog

    records = []
    remove = rlog.add_sink(lambda sev, name, msg, t: records.append(msg))
    try:
        with rlog.silenced():
            rlog.get_logger('quiet').warning('inside')
        with pytest.raises(RuntimeError), rlog.silenced():
            raise RuntimeError('stop')
        assert rlog.stream_output
        rlog.get_logger('quiet').warning('after')
    finally:
        remove()
    err = capsys.readouterr().err
    assert records == ['inside', 'after'] and 'inside' not in err and 'after' in err
