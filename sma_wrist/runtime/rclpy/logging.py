"""rclpy.logging with RcutilsLogger semantics (rclpy/impl/rcutils_logger.py, Humble).

Filters (``throttle_duration_sec`` [+ ``throttle_time_source_type``], ``skip_first``,
``once``) keep per-call-site state, keyed like rclpy by the caller's code location; their
combination rules and errors are rclpy's.  Output goes to stderr in rcutils' default
format ``[SEVERITY] [sec.nsec] [name]: message`` with the *virtual* system time, and to any
sinks registered with :func:`add_sink` (tests, diagnostics); inside a ``Runtime`` the stamp is the graph's time
(:func:`set_stamp_source`: /clock once a node publishes it).  One deliberate difference:
a throttled call site always logs its first call (rclpy compares against a last-logged
time of 0, which on a virtual clock starting at 0 would swallow the first message).
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator
from enum import IntEnum
from typing import Any

from .clock import Clock

__all__ = [
    'LoggingSeverity',
    'RcutilsLogger',
    'add_sink',
    'get_logger',
    'get_logger_effective_level',
    'set_logger_level',
    'set_stamp_source',
]


class LoggingSeverity(IntEnum):
    UNSET = 0
    DEBUG = 10
    INFO = 20
    WARN = 30
    ERROR = 40
    FATAL = 50


_levels: dict[str, LoggingSeverity] = {}
_default_level = LoggingSeverity.INFO
Sink = Callable[[LoggingSeverity, str, str, int], None]
_sinks: list[Sink] = []
stream_output = True  # print to stderr; tests/CLI may turn it off
_stamp_source: Callable[[], int] | None = None  # ns of a record; None: the virtual system time


def set_stamp_source(source: Callable[[], int] | None) -> None:
    """What the records are stamped with [ns] (None: the virtual system time). Under ROS a record carries the wall
    clock; the virtual steady clock is none, and on the hardware path it lags the device: hardware_bridge's timer
    ticks every half window and each tick waits for the device, so a 140 s run's log ended at 68 s while its bag
    went on to 140 s. A ``sma_wrist.runtime.launch.Runtime`` stamps the records with /clock once a node publishes it,
    the time base of the bag, the measurements and /diagnostics."""
    global _stamp_source
    _stamp_source = source


@contextlib.contextmanager
def silenced() -> Iterator[None]:
    """No record printed to stderr inside the block (sinks still get them), the previous setting after it: for the
    project's own tools that build nodes for their parameters or their speed. Not --log-level, which would set
    the process's level for good."""
    global stream_output
    before, stream_output = stream_output, False
    try:
        yield
    finally:
        stream_output = before


def add_sink(sink: Sink) -> Callable[[], None]:
    """Call sink(severity, logger_name, message, time_ns) for every emitted record."""
    _sinks.append(sink)
    return lambda: _sinks.remove(sink) if sink in _sinks else None


def _coerce(level: Any) -> LoggingSeverity:
    if isinstance(level, str):
        level = level.upper()
        return LoggingSeverity.WARN if level == 'WARNING' else LoggingSeverity[level]
    return LoggingSeverity(level)


def set_logger_level(name: str, level: Any) -> None:
    global _default_level
    lvl = _coerce(level)
    if name == '':
        _default_level = lvl
    else:
        _levels[name] = lvl


def get_logger_effective_level(name: str) -> LoggingSeverity:
    while name:
        lvl = _levels.get(name)
        if lvl is not None and lvl != LoggingSeverity.UNSET:
            return lvl
        name = name.rpartition('.')[0]
    return _default_level


_FILTER_PARAMS = {
    'throttle': ('throttle_duration_sec', 'throttle_time_source_type'),
    'skip_first': ('skip_first',),
    'once': ('once',),
}
_ALL_PARAMS = [p for ps in _FILTER_PARAMS.values() for p in ps]


def _detect_filters(kwargs: dict[str, Any]) -> list[str]:
    found = [f for f, ps in _FILTER_PARAMS.items() if any(kwargs.get(p) for p in ps)]
    for f in found:
        if f == 'throttle':
            if 'throttle_duration_sec' not in kwargs:
                raise TypeError(
                    'required parameter "throttle_duration_sec" not specified '
                    'but is required for the the logging filter "throttle"'
                )
            kwargs.setdefault('throttle_time_source_type', _DEFAULT_THROTTLE_CLOCK)
    for k in kwargs:
        if k not in _ALL_PARAMS:
            raise TypeError(f'parameter "{k}" is not one of the recognized logging options "{_ALL_PARAMS}"')
    return found


class _Site:
    __slots__ = ('name', 'severity', 'filters', 'params', 'last', 'once_done', 'skipped')

    def __init__(self, name: str, severity: LoggingSeverity, filters: list[str], params: dict[str, Any]) -> None:
        self.name = name
        self.severity = severity
        self.filters = filters
        self.params = params
        self.last: int | None = None
        self.once_done = False
        self.skipped = False


class RcutilsLogger:
    def __init__(self, name: str = '') -> None:
        self.name = name
        self.contexts: dict[tuple[str, int, int], _Site] = {}

    def get_child(self, name: str) -> RcutilsLogger:
        if not name:
            raise ValueError('Child logger name must not be empty.')
        return RcutilsLogger(f'{self.name}.{name}' if self.name else name)

    def set_level(self, level: Any) -> None:
        set_logger_level(self.name, level)

    def get_effective_level(self) -> LoggingSeverity:
        return get_logger_effective_level(self.name)

    def is_enabled_for(self, severity: Any) -> bool:
        return _coerce(severity) >= get_logger_effective_level(self.name)

    def log(self, message: Any, severity: Any, **kwargs: Any) -> bool:
        severity = _coerce(severity)
        if severity < get_logger_effective_level(self.name):
            return False
        name = kwargs.pop('name', self.name)
        filters = _detect_filters(kwargs)
        frame = sys._getframe(1)
        while frame.f_code.co_filename == __file__:  # skip info()/warn()/... wrappers
            frame = frame.f_back
        key = (frame.f_code.co_filename, frame.f_lineno, frame.f_lasti)
        site = self.contexts.get(key)
        if site is None:
            site = _Site(name, severity, filters, {p: kwargs.get(p) for p in _ALL_PARAMS})
            if 'throttle' in filters and not isinstance(kwargs['throttle_time_source_type'], Clock):
                raise ValueError(
                    'Received throttle_time_source_type of "{}" is not a clock instance'.format(
                        kwargs['throttle_time_source_type']
                    )
                )
            self.contexts[key] = site
        else:
            if severity != site.severity:
                raise ValueError('Logger severity cannot be changed between calls.')
            if name != site.name:
                raise ValueError('Logger name cannot be changed between calls.')
            if filters != site.filters:
                raise ValueError('Requested logging filters cannot be changed between calls.')
            for f in filters:
                if any(site.params[p] != kwargs.get(p) for p in _FILTER_PARAMS[f]):
                    raise ValueError('Logging filter parameters cannot be changed between calls.')
        for f in site.filters:
            if f == 'throttle':
                now = site.params['throttle_time_source_type']._now_ns()
                if site.last is not None and now < site.last + site.params['throttle_duration_sec'] * 1e9:
                    return False
                site.last = now
            elif f == 'skip_first':
                if not site.skipped:
                    site.skipped = True
                    return False
            elif f == 'once':
                if site.once_done:
                    return False
                site.once_done = True
        _emit(severity, name, str(message))
        return True

    def debug(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.DEBUG, **kwargs)

    def info(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.INFO, **kwargs)

    def warning(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.WARN, **kwargs)

    def warn(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.WARN, **kwargs)

    def error(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.ERROR, **kwargs)

    def fatal(self, message: Any, **kwargs: Any) -> bool:
        return self.log(message, LoggingSeverity.FATAL, **kwargs)


_DEFAULT_THROTTLE_CLOCK = Clock()


def _emit(severity: LoggingSeverity, name: str, message: str) -> None:
    t = _DEFAULT_THROTTLE_CLOCK._now_ns() if _stamp_source is None else _stamp_source()
    for sink in list(_sinks):
        sink(severity, name, message, t)
    if stream_output:
        sec, nsec = divmod(t, 10**9)
        sys.stderr.write(f'[{severity.name}] [{sec}.{nsec:09d}] [{name}]: {message}\n')


_root = RcutilsLogger()


def get_logger(name: str) -> RcutilsLogger:
    if not name:
        raise ValueError('Logger name must not be empty.')
    return _root.get_child(name)


def initialize() -> None:
    pass


def shutdown() -> None:
    pass


def clear_config() -> None:
    _levels.clear()


def get_logging_directory() -> str:
    return ''
