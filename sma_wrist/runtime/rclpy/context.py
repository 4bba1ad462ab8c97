"""rclpy.context.Context for the embedded runtime: holds the parsed global arguments and
the in-process Graph of every node created in it."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

from sma_wrist.runtime.arguments import RosArguments, parse_ros_args
from sma_wrist.runtime.graph import Graph
from sma_wrist.runtime.vclock import VCLOCK


class Context:
    def __init__(self) -> None:
        self._ok = False
        self._initialized = False
        self._args = RosArguments()
        self._graph = Graph()
        self._callbacks: list[Callable[[], None]] = []
        self._domain_id = 0

    @property
    def handle(self) -> Context:
        return self

    def init(
        self, args: Iterable[str] | None = None, *, initialize_logging: bool = True, domain_id: int | None = None
    ) -> None:
        if self._initialized:
            raise RuntimeError('Context.init() must only be called once')
        self._args = parse_ros_args(args)
        self._graph = Graph()
        self._domain_id = domain_id or 0
        VCLOCK.reset(VCLOCK.system_epoch_ns)
        from . import logging as _logging

        for name, level in self._args.log_levels.items():
            _logging.set_logger_level(name, level)
        self._initialized = True
        self._ok = True

    def ok(self) -> bool:
        return self._ok

    def shutdown(self) -> None:
        if not self._ok:
            raise RuntimeError('Context must be initialized before it can be shutdown')
        self._ok = False
        callbacks, self._callbacks = self._callbacks, []
        for cb in callbacks:
            cb()

    def try_shutdown(self) -> None:
        if self._ok:
            self.shutdown()

    def on_shutdown(self, callback: Callable[[], None]) -> None:
        if not callable(callback):
            raise TypeError('callback should be a callable, got {}', type(callback))
        if not self._ok:
            callback()
        else:
            self._callbacks.append(callback)

    def get_domain_id(self) -> int:
        return self._domain_id

    @property
    def args(self) -> RosArguments:
        return self._args

    @property
    def graph(self) -> Graph:
        return self._graph

    def __enter__(self) -> Context:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.try_shutdown()
