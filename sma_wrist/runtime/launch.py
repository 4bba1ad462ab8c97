"""Run a set of node classes in one process on virtual time, optionally recording a bag.

This is the embedded counterpart of a launch file + ``ros2 bag record``::

    from sma_wrist import runtime
    runtime.activate()
    from sma_wrist.runtime.launch import Runtime, run_nodes

    result = run_nodes([PlantSim, TemController], duration=10.0,
                       params={'/**': {'use_sim_time': True},
                               '/plant_sim': {'use_sim_time': False}},
                       bag='runs/step', args=['--ros-args', '--params-file', 'config/x.yaml'])

``duration`` is measured in sim time (the last /clock message) when any node uses sim
time, otherwise in virtual steady time (``until='auto'``).
"""

from __future__ import annotations

import time as _wall
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .arguments import params_from_tree
from .errors import ActivationError, GraphError
from .vclock import VCLOCK


@dataclass
class RunResult:
    reason: str  # 'time', 'condition', 'idle', 'shutdown', 'max_callbacks'
    steady_ns: int  # virtual steady time at the end
    sim_ns: int | None  # last /clock time seen (None if no /clock)
    callbacks: int
    wall_s: float
    bag: str | None = None
    recorded: int = 0

    @property
    def real_time_factor(self) -> float:
        t = (self.sim_ns if self.sim_ns is not None else self.steady_ns) / 1e9
        return t / self.wall_s if self.wall_s > 0 else float('inf')


def _rclpy() -> Any:
    from . import using_embedded

    if not using_embedded():
        raise ActivationError(
            'the embedded runtime is not active: call '
            'sma_wrist.runtime.activate() first (ROS 2 sourced? use ros2 launch)'
        )
    from . import rclpy

    return rclpy


class Runtime:
    """One rclpy context + executor on virtual time.

    Parameters
    ----------
    args:
        Global ROS arguments, as passed to ``rclpy.init(args=...)``.
    params:
        ``{node_pattern: {param: value}}`` applied like a params file given after ``args``
        (patterns as in params files: ``/**``, ``/plant_sim``, ``plant_sim``).
    system_epoch_ns:
        SYSTEM time at virtual time 0.
    delivery:
        A :class:`sma_wrist.runtime.delivery.DeliveryModel` (per-topic latency and seeded jitter,
        as DDS shows); None (default) delivers every message at once, deterministically.
    """

    def __init__(
        self,
        args: Sequence[str] | None = None,
        *,
        params: Mapping[str, Mapping[str, Any]] | None = None,
        system_epoch_ns: int = 0,
        delivery: Any = None,
    ) -> None:
        rclpy = _rclpy()
        from .rclpy.context import Context
        from .rclpy.executors import SingleThreadedExecutor

        if rclpy.ok():
            raise GraphError('rclpy is already initialised; shut it down before creating a Runtime')
        VCLOCK.system_epoch_ns = int(system_epoch_ns)
        from .rclpy.signals import SignalHandlerOptions

        # in-process tools (run, experiment, sweep) handle Ctrl-C themselves: they stop the graph and keep the bag
        rclpy.init(args=list(args) if args is not None else None, signal_handler_options=SignalHandlerOptions.NO)
        self.context: Context = rclpy.get_default_context()
        if params:
            tree = {node: {'ros__parameters': dict(values)} for node, values in params.items()}
            self.context.args.params.extend(params_from_tree(tree, 'Runtime(params=...)'))
        # delivery: a runtime.delivery.DeliveryModel (latency/jitter per topic); None delivers at once
        self.context.graph.delivery = delivery
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Any] = []
        self.recorders: list[Any] = []
        self.attached: list[Any] = []  # live servers and pacers: detached, and servers stopped, by close()
        self._sim_ns: int | None = None
        self.context.graph.add_tap(self._on_clock, ['/clock'])
        from .rclpy import logging as rlog

        rlog.set_stamp_source(self._log_time_ns)  # the log on the bag's time base, not the virtual steady clock

    def _on_clock(self, topic: Any, msg: Any, t_ns: int) -> None:
        self._sim_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec

    # -- graph -------------------------------------------------------------
    def add(self, node_or_factory: Any, *args: Any, **kwargs: Any) -> Any:
        """Add a Node instance, or construct one from a class/factory and add it."""
        from .rclpy.node import Node

        node = node_or_factory if isinstance(node_or_factory, Node) else node_or_factory(*args, **kwargs)
        if not isinstance(node, Node):
            raise GraphError(f'{node_or_factory!r} did not produce an rclpy Node')
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def _record_time_ns(self) -> int:
        return self._sim_ns if self._sim_ns is not None else VCLOCK.steady_ns

    def _log_time_ns(self) -> int:
        return self._sim_ns if self._sim_ns is not None else VCLOCK.system_ns

    def add_nodes(self, factories: Iterable[Any]) -> list[Any]:
        return [self.add(f) for f in factories]

    def record(self, path: str | Path, topics: Iterable[str] | None = None, **kwargs: Any) -> Any:
        """Start a BagRecorder on this context; it is closed by close()/the with block."""
        from sma_wrist.bag import BagRecorder

        # one clock for every message's log time, as ros2 bag record with --use-sim-time: the
        # publishers' own clocks differ (hardware_bridge polls its steady clock twice per window)
        kwargs.setdefault('clock_ns', self._record_time_ns)
        rec = BagRecorder(path, topics, context=self.context, **kwargs).start()
        self.recorders.append(rec)
        return rec

    def serve_live(self, server: Any) -> Any:
        """Serve this graph's topics on a :class:`sma_wrist.runtime.live.LiveServer` (log times on the bag's
        clock); the server is stopped by close()/the with block."""
        server.attach(self.context, self._record_time_ns)
        self.attached.append(server)
        return server

    def pace(self, real_time_factor: float) -> Any:
        """Hold /clock to ``real_time_factor`` x real time (:class:`sma_wrist.runtime.live.RealTimePacer`)."""
        from .live import RealTimePacer

        pacer = RealTimePacer(real_time_factor).attach(self.context)
        self.attached.append(pacer)
        return pacer

    # -- time --------------------------------------------------------------
    @property
    def steady_ns(self) -> int:
        return VCLOCK.steady_ns

    @property
    def sim_ns(self) -> int | None:
        return self._sim_ns

    def uses_sim_time(self) -> bool:
        return any(n.get_clock().ros_time_is_active for n in self.nodes)

    def run_until(self, t_end: float, *, until: str = 'auto', stop_when: Callable[[], bool] | None = None) -> RunResult:
        """Run until ``t_end`` seconds of virtual steady time (``until='steady'``) or of sim
        time (``until='sim'``: the last /clock message); ``'auto'`` picks sim time when
        any node has ``use_sim_time`` active.  Work due at the end instant is completed."""
        mode = ('sim' if self.uses_sim_time() else 'steady') if until == 'auto' else until
        end_ns = int(round(t_end * 1e9))
        wall0 = _wall.perf_counter()
        cb0 = self.executor.callbacks_run
        ex = self.executor
        if mode == 'steady':
            reason = ex.run_until(end_ns, stop_when=stop_when)
        elif mode == 'sim':

            def done() -> bool:
                return (self._sim_ns is not None and self._sim_ns >= end_ns) or (stop_when is not None and stop_when())

            reason = ex.run_until(None, stop_when=done)
            if reason == 'condition':
                if stop_when is None or not stop_when():
                    reason = 'time'
                ex.run_until(VCLOCK.steady_ns)  # finish the cascade of this instant
            elif reason == 'idle':
                raise GraphError(
                    f'sim time stopped at {self._sim_ns} ns before {end_ns} ns: '
                    'no node publishes /clock (or its timers stopped)'
                )
        else:
            raise ValueError(f"until must be 'auto', 'steady' or 'sim', not {until!r}")
        return RunResult(
            reason,
            VCLOCK.steady_ns,
            self._sim_ns,
            ex.callbacks_run - cb0,
            _wall.perf_counter() - wall0,
            str(self.recorders[0].path) if self.recorders else None,
            sum(r.count for r in self.recorders),
        )

    def spin_for(self, duration: float, **kwargs: Any) -> RunResult:
        """Run for ``duration`` seconds from the current (steady or sim) time."""
        mode = kwargs.get('until', 'auto')
        sim = (mode == 'sim') or (mode == 'auto' and self.uses_sim_time())
        start = (self._sim_ns or 0) if sim else VCLOCK.steady_ns
        return self.run_until(start / 1e9 + duration, **kwargs)

    # -- teardown ----------------------------------------------------------
    def close(self) -> None:
        """Close recorders (complete bags), destroy nodes, shut rclpy down. Idempotent."""
        rclpy = _rclpy()
        errors = []
        for rec in self.recorders:
            try:
                rec.close()
            except Exception as exc:  # noqa: BLE001 - keep closing the others
                errors.append(exc)
        for item in self.attached:
            item.close()
        self.attached = []
        for node in self.nodes:
            node.destroy_node()
        self.nodes = []
        rclpy.try_shutdown()
        from .rclpy import logging as rlog

        rlog.set_stamp_source(None)
        if errors:
            raise errors[0]

    def __enter__(self) -> Runtime:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def run_nodes(
    node_classes: Iterable[Any],
    duration: float,
    *,
    args: Sequence[str] | None = None,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    bag: str | Path | None = None,
    topics: Iterable[str] | None = None,
    until: str = 'auto',
    stop_when: Callable[[], bool] | None = None,
) -> RunResult:
    """Construct the node classes (in order), run for ``duration`` s, record ``bag``.

    The bag is closed even on Ctrl-C or an exception in a callback, so everything up to
    the interrupt is readable.
    """
    with Runtime(args, params=params) as rt:
        if bag is not None:
            rt.record(bag, topics)
        rt.add_nodes(node_classes)
        return rt.run_until(duration, until=until, stop_when=stop_when)
