"""Helpers the launch files import (kept in the package so both launch files share them).

Why a file per node: a ``parameters=[{...}]`` dict is written by launch_ros under ``/**``,
and rcl merges every params file into one table keyed by node name *in order of first
appearance*, which rclpy then applies key by key (rclpy ``_populate_node_parameters_from_rcl_params``).
config/wrist.yaml's own ``plant_sim:`` / ``adaptive_controller:`` / ``hardware_bridge:``
sections come after its ``/**`` and would silently win over controller:=, payload_kg:= and
port:= (found running the launch files under ROS 2 Humble). Written under the node's own
name, a later file's value replaces the earlier one in that node's entry.
"""

from __future__ import annotations

import atexit
import os
import re
import shutil
import tempfile
from collections.abc import Mapping
from typing import Any

import yaml

_params_dir: str | None = None


def _launch_dir() -> str:
    """This process's folder for the files below, removed when it exits. The launch process outlives
    every node it starts (they read their files at start-up), and a file per node and launch left
    in the temporary folder adds up over many runs."""
    global _params_dir
    if _params_dir is None or not os.path.isdir(_params_dir):
        _params_dir = tempfile.mkdtemp(prefix='sma_wrist_launch_')
        atexit.register(_remove, _params_dir, os.getpid())
    return _params_dir


def _remove(path: str, owner_pid: int) -> None:
    if os.getpid() == owner_pid:  # a forked child that exits normally inherits the hook, not the folder
        shutil.rmtree(path, ignore_errors=True)


def node_params_file(node_name: str, values: Mapping[str, Any]) -> str:
    """Path of a new params file that sets ``values`` under ``node_name`` (deleted when this process exits)."""
    safe = re.sub(r'\W', '_', node_name)  # '/**' is a valid node key, not a file name
    fd, path = tempfile.mkstemp(prefix=f'{safe}_', suffix='.yaml', dir=_launch_dir())
    with os.fdopen(fd, 'w') as f:
        yaml.safe_dump({node_name: {'ros__parameters': dict(values)}}, f)
    return path


def payload_override(text: str) -> dict[str, float]:
    """The source node's override for payload_kg:= (``''``, the default: none, so the params files' payload stands;
    a payload_kg:= default of 0.3 overrode a params_file's payload_kg in silence)."""
    return {} if text.strip() == '' else {'payload_kg': float(text)}


#: nodes whose exit leaves the rest of the graph meaningless (no plant or device, no /clock: every
#: other node would wait forever); each launch file gives them ``on_exit`` = log + shut down with
#: this reason, and the embedded launcher (sma_wrist.runtime.launch_file) honours the same actions
REQUIRED_EXIT_REASONS = {
    'plant_sim': 'plant_sim exited: the graph has no plant and no /clock, shutting the launch down',
    'hardware_bridge': 'hardware_bridge exited: the graph has no device and no /clock, shutting the launch down',
}


class RequiredNodeFailed(RuntimeError):
    """A required node exited with a non-zero code: raised from its ``on_exit`` so that ``ros2 launch`` exits 1.

    launch's ``LaunchService.run`` (Humble 1.0.x, Jazzy 3.4.x) returns 1 only when an exception escapes an action or
    an event handler ("Caught exception in launch (see debug for traceback): ..."), which also shuts the launch down;
    a ``Shutdown`` action, whatever its reason, ends it with 0, so a script could not tell a refused start from a
    normal end."""


def on_exit_actions(executable: str) -> list | None:
    """``on_exit`` of a launch_ros Node: for a required node, log the reason and shut the launch down -- unless the
    launch is already shutting down (a user's Ctrl-C ends plant_sim too, and its exit is then no fault: under
    Humble and Jazzy every Ctrl-C logged "plant_sim exited: the graph has no plant..."). A non-zero exit code (a
    refused start exits 2) shuts it down by :class:`RequiredNodeFailed`, so that ``ros2 launch`` exits 1; an exit
    with 0 (the node stopped on a signal of its own) by ``Shutdown``, and ``ros2 launch`` exits 0."""
    reason = REQUIRED_EXIT_REASONS.get(executable)
    if reason is None:
        return None
    from launch.actions import LogInfo, OpaqueFunction, Shutdown  # only launch files call this

    def unless_shutting_down(context: Any) -> list:
        if context.is_shutdown:
            return []
        code = getattr(getattr(context.locals, 'event', None), 'returncode', None)  # launch's ProcessExited
        if not code:
            return [LogInfo(msg=reason), Shutdown(reason=reason)]
        raise RequiredNodeFailed(f'{executable} exited with code {code}: ' + reason.split(': ', 1)[1])

    return [OpaqueFunction(function=unless_shutting_down)]


def node_parameters(defaults: str, extra: str, executable: str, values: Mapping[str, Any]) -> list[str]:
    """``parameters`` of a launch_ros Node: config/wrist.yaml, the user's params_file:= if one was given (its
    default is none: defaulting to config/wrist.yaml put that file twice on every node's command line), then the
    node's own overrides (:func:`node_params_file`)."""
    return [defaults, *([extra] if extra.strip() else []), node_params_file(executable, values)]


def graph_specs(
    source: str, source_overrides: Mapping[str, Any], controller: str, monitor: bool = False
) -> list[tuple[str, dict[str, Any]]]:
    """(executable, its own parameter overrides) of every node of the wrist graph, in start order.

    ``source`` owns /clock (plant_sim or hardware_bridge) and runs on its own clock; every other
    node runs on /clock. The compensator only serves the inverse mode; ``monitor`` adds twin_monitor (optional:
    the graph does not depend on it).
    """
    specs = [
        (source, {'use_sim_time': False, **source_overrides}),
        ('trajectory_generator', {'use_sim_time': True}),
        ('adaptive_controller', {'use_sim_time': True, 'mode': controller}),
    ]
    if controller == 'inverse_adaptive':
        specs.append(('hysteresis_compensator', {'use_sim_time': True}))
    specs.append(('tem_controller', {'use_sim_time': True}))
    if monitor:
        specs.append(('twin_monitor', {'use_sim_time': True}))
    return specs


def flag(text: str) -> bool:
    """A launch argument's true / false (ros2 launch passes text)."""
    v = text.strip().lower()
    if v not in ('true', 'false', '1', '0', 'yes', 'no', ''):
        raise ValueError(f'{text!r} is not true or false')
    return v in ('true', '1', 'yes')


__all__ = [
    'REQUIRED_EXIT_REASONS',
    'RequiredNodeFailed',
    'flag',
    'graph_specs',
    'node_parameters',
    'node_params_file',
    'on_exit_actions',
    'payload_override',
]
