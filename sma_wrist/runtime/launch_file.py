"""Run the package's launch files (``launch/*.launch.py``) on the embedded runtime.

``ros2 launch`` is not available without ROS, so this provides the part of the ``launch`` /
``launch_ros`` API those files use, with its semantics, and runs the *same* file: argument
declarations (defaults, ``choices``), ``OpaqueFunction``, ``LaunchConfiguration``,
``PathJoinSubstitution``, ``FindPackageShare``, launch_ros ``Node`` (executable, name,
parameters, ``on_exit``), ``LogInfo`` and ``Shutdown(reason=...)``.

Under ros2 launch each ``Node`` is a process started with
``--ros-args -r __node:=<name> --params-file <f>...``; here each is constructed in one
context with exactly those arguments as its own (``use_global_arguments=False``). A node
that refuses to start is a process that exits 2 (``main_for``'s message is printed): its
``on_exit`` actions run with that exit in ``context.locals.event``, and a ``Shutdown`` ends the
launch with its reason, as ros2 launch does (launch ``ExecuteProcess(on_exit=...)``,
``actions/shutdown_action.py``); an action that raises ends it with ``return_code`` 1, as
``LaunchService.run`` does. A node that fails while running raises out of the run (one process here).
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import GraphError
from .launch import RunResult, Runtime


class LaunchFileError(GraphError):
    """A launch file or its arguments cannot be run (unknown action, bad argument value)."""


# -- the launch / launch_ros subset --------------------------------------------------------
class LaunchContext:
    def __init__(self, configurations: Mapping[str, str]) -> None:
        self.launch_configurations = dict(configurations)
        self.is_shutdown = False  # launch.LaunchContext's: a Shutdown is under way
        self.locals = types.SimpleNamespace()  # launch's: ``event`` while an event handler's actions run


@dataclass(frozen=True)
class ProcessExited:
    """What launch's ``ProcessExited`` event carries that on_exit actions read (``context.locals.event``)."""

    process_name: str
    returncode: int


def _perform(value: Any, context: LaunchContext) -> str:
    return value.perform(context) if hasattr(value, 'perform') else str(value)


class LaunchDescription:
    def __init__(self, initial_entities: Sequence[Any] | None = None) -> None:
        self.entities = list(initial_entities or [])


class DeclareLaunchArgument:
    def __init__(
        self,
        name: str,
        *,
        default_value: Any = None,
        description: str = '',
        choices: Sequence[str] | None = None,
        **_: Any,
    ) -> None:
        self.name, self.default_value, self.description = name, default_value, description
        self.choices = list(choices) if choices is not None else None


class OpaqueFunction:
    def __init__(
        self, *, function: Callable[..., Any], args: Sequence[Any] = (), kwargs: Mapping[str, Any] | None = None
    ) -> None:
        self.function, self.args, self.kwargs = function, list(args), dict(kwargs or {})


class LogInfo:
    def __init__(self, *, msg: Any) -> None:
        self.msg = msg


class Shutdown:
    def __init__(self, *, reason: Any = 'reason not given') -> None:
        self.reason = reason


class LaunchConfiguration:
    def __init__(self, variable_name: str, *, default: Any = None) -> None:
        self.variable_name, self.default = variable_name, default

    def perform(self, context: LaunchContext) -> str:
        if self.variable_name in context.launch_configurations:
            return context.launch_configurations[self.variable_name]
        if self.default is not None:
            return _perform(self.default, context)
        raise LaunchFileError(f"launch configuration '{self.variable_name}' does not exist")


class PathJoinSubstitution:
    def __init__(self, substitutions: Sequence[Any]) -> None:
        self.substitutions = list(substitutions)

    def perform(self, context: LaunchContext) -> str:
        return os.path.join(*(_perform(s, context) for s in self.substitutions))


class FindPackageShare:
    def __init__(self, package: str) -> None:
        self.package = package

    def perform(self, context: LaunchContext) -> str:
        from sma_wrist.share import PACKAGE, share_path

        if self.package != PACKAGE:
            raise LaunchFileError(f'package {self.package!r} is not available on the embedded runtime')
        return str(share_path('config/wrist.yaml').parent.parent)


class Node:
    def __init__(
        self,
        *,
        executable: str,
        package: str | None = None,
        name: str | None = None,
        parameters: Sequence[Any] = (),
        on_exit: Sequence[Any] | None = None,
        output: Any = None,
        **_: Any,
    ) -> None:
        self.package, self.executable, self.name = package, executable, name or executable
        self.parameters, self.on_exit = list(parameters), list(on_exit or [])


_MODULES = {
    'launch': {'LaunchDescription': LaunchDescription, 'LaunchContext': LaunchContext},
    'launch.actions': {
        'DeclareLaunchArgument': DeclareLaunchArgument,
        'OpaqueFunction': OpaqueFunction,
        'LogInfo': LogInfo,
        'Shutdown': Shutdown,
    },
    'launch.substitutions': {'LaunchConfiguration': LaunchConfiguration, 'PathJoinSubstitution': PathJoinSubstitution},
    'launch_ros': {},
    'launch_ros.actions': {'Node': Node},
    'launch_ros.substitutions': {'FindPackageShare': FindPackageShare},
}


class _LaunchModules:
    """``launch`` / ``launch_ros`` in sys.modules while a launch file is loaded and evaluated."""

    def __enter__(self) -> _LaunchModules:
        self._saved = {name: sys.modules.get(name) for name in _MODULES}
        for name, attrs in _MODULES.items():
            mod = types.ModuleType(name, 'embedded stand-in (sma_wrist.runtime.launch_file)')
            mod.__dict__.update(attrs)
            if '.' not in name:
                mod.__path__ = []  # a package, so 'launch.actions' imports
            sys.modules[name] = mod
        return self

    def __exit__(self, *exc: Any) -> None:
        for name, mod in self._saved.items():
            if mod is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = mod


# -- running ---------------------------------------------------------------------------------
@dataclass
class LaunchResult:
    reason: str  # 'time' (ran for the duration) or 'shutdown' (a Shutdown action, or an action that raised)
    shutdown_reason: str | None = None
    return_code: int = 0  # what ros2 launch returns: 1 when an action raised (LaunchService.run), else 0
    exits: dict[str, int] = field(default_factory=dict)  # node name -> exit code of nodes that ended
    started: list[str] = field(default_factory=list)  # node names running when the launch ended
    log: list[str] = field(default_factory=list)  # LogInfo messages
    run: RunResult | None = None


def node_class(executable: str) -> type:
    """The node class behind a console script of this package (``sma_wrist.nodes.<executable>``)."""
    from sma_wrist.nodes.common import WristNode

    try:
        mod = importlib.import_module(f'sma_wrist.nodes.{executable}')
    except ModuleNotFoundError:
        raise LaunchFileError(f'executable {executable!r} not found in package sma_wrist') from None
    found = [
        c
        for c in vars(mod).values()
        if inspect.isclass(c) and issubclass(c, WristNode) and c.__module__ == mod.__name__
    ]
    if len(found) != 1:
        raise LaunchFileError(f'sma_wrist.nodes.{executable} defines {len(found)} node classes, expected 1')
    return found[0]


def _load(path: Path) -> LaunchDescription:
    spec = importlib.util.spec_from_file_location(f'_sma_wrist_launch_{path.stem.replace(".", "_")}', path)
    if spec is None or spec.loader is None:
        raise LaunchFileError(f'cannot load launch file {path}')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.generate_launch_description()


def _configure(desc: LaunchDescription, arguments: Mapping[str, str]) -> tuple[LaunchContext, list[Node]]:
    context = LaunchContext({})
    nodes: list[Node] = []
    for entity in desc.entities:
        if isinstance(entity, DeclareLaunchArgument):
            if entity.name in arguments:
                value = str(arguments[entity.name])
            elif entity.default_value is not None:
                value = _perform(entity.default_value, context)
            else:
                raise LaunchFileError(f"Included launch description missing required argument '{entity.name}'")
            if entity.choices is not None and value not in entity.choices:
                # launch's own wording (actions/declare_launch_argument.py)
                raise LaunchFileError(
                    f"Argument '{entity.name}' provided value '{value}' is not valid. "
                    f'Valid options are: {entity.choices}'
                )
            context.launch_configurations[entity.name] = value
        elif isinstance(entity, OpaqueFunction):
            nodes += entity.function(context, *entity.args, **entity.kwargs) or []
        elif isinstance(entity, Node):
            nodes.append(entity)
        else:
            raise LaunchFileError(f'{type(entity).__name__} is not supported by the embedded launcher')
    return context, nodes


def _on_exit(
    actions: Sequence[Any],
    context: LaunchContext,
    result: LaunchResult,
    print_fn: Callable[[str], None],
    event: ProcessExited | None = None,
) -> None:
    """A node's ``on_exit`` actions, ``event`` in ``context.locals``: LogInfo, Shutdown (the first one's reason ends the
    launch), OpaqueFunction (its actions in turn, given the context). An action that raises ends the launch with
    return code 1 and launch's message, as ``LaunchService.run`` does (launch_service.py, Humble and Jazzy)."""
    saved, context.locals = context.locals, types.SimpleNamespace(**vars(context.locals), event=event)
    try:
        _run_actions(actions, context, result, print_fn)
    except LaunchFileError:
        raise
    except Exception as exc:  # noqa: BLE001 - launch catches every exception of an action the same way
        message = f'Caught exception in launch (see debug for traceback): {exc}'
        print_fn(f'[ERROR] [launch]: {message}')
        result.return_code = 1
        if result.shutdown_reason is None:
            result.reason, result.shutdown_reason = 'shutdown', message
        context.is_shutdown = True
    finally:
        context.locals = saved


def _run_actions(
    actions: Sequence[Any], context: LaunchContext, result: LaunchResult, print_fn: Callable[[str], None]
) -> None:
    for a in actions:
        if isinstance(a, LogInfo):
            text = _perform(a.msg, context)
            result.log.append(text)
            print_fn(f'[INFO] [launch.user]: {text}')
        elif isinstance(a, Shutdown):
            if result.shutdown_reason is None:
                result.reason, result.shutdown_reason = 'shutdown', _perform(a.reason, context)
                context.is_shutdown = True
        elif isinstance(a, OpaqueFunction):
            _run_actions(a.function(context, *a.args, **a.kwargs) or [], context, result, print_fn)
        else:
            raise LaunchFileError(f'{type(a).__name__} in on_exit is not supported')


def run_launch_file(
    path: str | Path,
    arguments: Mapping[str, Any] | None = None,
    duration: float = 1.0,
    *,
    bag: str | Path | None = None,
    print_fn: Callable[[str], None] = print,
) -> LaunchResult:
    """``ros2 launch <path> name:=value...`` for ``duration`` s of sim time, on the embedded runtime."""
    from sma_wrist.nodes.common import start_up_refusal

    path = Path(path)
    with _LaunchModules():
        context, nodes = _configure(_load(path), {k: str(v) for k, v in (arguments or {}).items()})
        result = LaunchResult('time')
        with Runtime() as rt:
            if bag is not None:
                rt.record(bag)
            for action in nodes:
                cls = node_class(action.executable)
                args = ['--ros-args', '-r', f'__node:={action.name}']
                for p in action.parameters:
                    args += ['--params-file', _perform(p, context)]
                try:
                    rt.add(cls, cli_args=args, use_global_arguments=False)
                except Exception as e:  # noqa: BLE001 - a refusal is the process's exit 2
                    message = start_up_refusal(e, cls)
                    if message is None:
                        raise
                    print_fn(f'[{action.name}] {message}')
                    result.exits[action.name] = 2
                    _on_exit(action.on_exit, context, result, print_fn, ProcessExited(action.name, 2))
                    continue
                result.started.append(action.name)
            if result.reason != 'shutdown':
                # a graph left without its clock raises GraphError (ros2 launch: waits until Ctrl-C)
                result.run = rt.run_until(duration, until='sim')
    return result


__all__ = ['LaunchFileError', 'LaunchResult', 'node_class', 'run_launch_file']
