"""ROS 2 command line arguments and params files, as rcl parses them (Humble).

Supported inside ``--ros-args ... [--]``:

* ``-p/--param [node:]name:=value`` (value parsed as YAML with rcl's scalar rules),
* ``--params-file FILE`` (``node: {ros__parameters: {...}}``; node keys may be
  namespaced and use ``*`` / ``/**`` wildcards; nested dicts give dotted names),
* ``-r/--remap [node:]from:=to`` including ``__node``/``__name`` and ``__ns``,
* ``--log-level [name:=]LEVEL``; ``--enclave``, ``--disable-*``/``--enable-*`` flags are
  accepted and ignored.

Rules are kept in command-line order and merged as rcl does (:func:`overrides_for`: one
table keyed by node name in order of first appearance, later values replacing earlier ones
within a key).  rclpy
(src/rclpy/node.cpp ``_populate_node_parameters_from_rcl_params``) matches a node key by
turning ``/*`` into ``(/\\w+)`` and testing the node's fully-qualified name, after
prefixing keys that lack a leading ``/``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import ArgumentError

_TRUE = {'Y', 'y', 'yes', 'Yes', 'YES', 'true', 'True', 'TRUE', 'on', 'On', 'ON'}
_FALSE = {'N', 'n', 'no', 'No', 'NO', 'false', 'False', 'FALSE', 'off', 'Off', 'OFF'}
_INT = re.compile(r'[-+]?\d+')
_FLOAT = re.compile(r'[-+]?(\d+\.?\d*([eE][-+]?\d+)?|\.\d+([eE][-+]?\d+)?)')
_SPECIAL_FLOAT = {
    '.nan': math.nan,
    '.NaN': math.nan,
    '.NAN': math.nan,
    '.inf': math.inf,
    '.Inf': math.inf,
    '.INF': math.inf,
    '-.inf': -math.inf,
    '-.Inf': -math.inf,
    '-.INF': -math.inf,
}


def parse_scalar(text: str) -> Any:
    """A plain (unquoted) YAML scalar with rcl_yaml_param_parser's typing rules."""
    if text in _TRUE:
        return True
    if text in _FALSE:
        return False
    if _INT.fullmatch(text):
        return int(text)
    if _FLOAT.fullmatch(text):
        return float(text)
    if text in _SPECIAL_FLOAT:
        return _SPECIAL_FLOAT[text]
    return text


class _RclLoader(yaml.SafeLoader):
    """SafeLoader whose plain scalars are typed like rcl's, quoted ones stay strings."""


_RclLoader.yaml_implicit_resolvers = {}


def _construct_str(loader: _RclLoader, node: yaml.ScalarNode) -> Any:
    value = loader.construct_scalar(node)
    if node.style is None:  # plain scalar
        return parse_scalar(str(value))
    return value


_RclLoader.add_constructor('tag:yaml.org,2002:str', _construct_str)


def yaml_problem(exc: yaml.YAMLError) -> str:
    """PyYAML's error in one line: the problem and where (its message spans several lines
    with a copy of the offending text, which a CLI's one-line ``error:`` cannot hold)."""
    problem = getattr(exc, 'problem', None)
    mark = getattr(exc, 'problem_mark', None)
    if not problem:
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return problem + (f' at line {mark.line + 1}, column {mark.column + 1}' if mark is not None else '')


def load_yaml(text: str) -> Any:
    return yaml.load(text, Loader=_RclLoader)  # noqa: S506 - SafeLoader subclass


def _check_value(value: Any, name: str, where: str) -> Any:
    if isinstance(value, list):
        kinds = {type(v) for v in value}
        if len(kinds) > 1:
            raise ArgumentError(
                f'parameter {name!r}: sequence items must all have one type, got {sorted(k.__name__ for k in kinds)}',
                where,
            )
        if kinds and next(iter(kinds)) not in (bool, int, float, str):
            raise ArgumentError(f'parameter {name!r}: unsupported sequence item type', where)
        return value
    if isinstance(value, (bool, int, float, str)):
        return value
    raise ArgumentError(f'parameter {name!r}: unsupported value {value!r}', where)


def _flatten(prefix: str, tree: Any, out: list[tuple[str, Any]], where: str) -> None:
    if isinstance(tree, dict):
        for key, sub in tree.items():
            _flatten(f'{prefix}.{key}' if prefix else str(key), sub, out, where)
    else:
        if not prefix:
            raise ArgumentError('ros__parameters must be a mapping', where)
        out.append((prefix, _check_value(tree, prefix, where)))


@dataclass(frozen=True)
class ParamRule:
    node: str  # node-name pattern as written ('/**' for all nodes)
    name: str
    value: Any
    source: str


@dataclass(frozen=True)
class RemapRule:
    node: str | None
    src: str
    dst: str


@dataclass
class RosArguments:
    params: list[ParamRule] = field(default_factory=list)
    remaps: list[RemapRule] = field(default_factory=list)
    log_levels: dict[str, str] = field(default_factory=dict)
    unparsed: list[str] = field(default_factory=list)


def load_params_file(path: str | Path) -> list[ParamRule]:
    """Rules of a ROS 2 params file, in file order."""
    p = Path(path)
    where = str(p)
    try:
        text = p.read_text(encoding='utf-8')
    except OSError as exc:
        raise ArgumentError(f'cannot read params file: {exc.strerror}', where) from None
    except UnicodeDecodeError as exc:  # a binary file or another encoding: rcl reads UTF-8 YAML only
        raise ArgumentError(
            f'not a UTF-8 text file (byte {exc.start}: {exc.reason}); a params file is YAML text', where
        ) from None
    try:
        doc = load_yaml(text)
    except yaml.YAMLError as exc:
        raise ArgumentError(f'invalid YAML: {yaml_problem(exc)}', where) from None
    return params_from_tree(doc, where)


def params_from_tree(doc: Any, where: str) -> list[ParamRule]:
    """Rules from an already-loaded params tree (``{node: {ros__parameters: {...}}}``)."""
    if doc is None:
        return []
    if not isinstance(doc, dict):
        raise ArgumentError('top level must be a mapping of node names', where)
    rules: list[ParamRule] = []

    def walk(prefix: str, tree: Any) -> None:
        if not isinstance(tree, dict):
            raise ArgumentError(f'node entry {prefix!r} must be a mapping', where)
        for key, sub in tree.items():
            if key == 'ros__parameters':
                flat: list[tuple[str, Any]] = []
                _flatten('', sub, flat, where)
                rules.extend(ParamRule(prefix or '/**', n, v, where) for n, v in flat)
            else:
                # nested namespace keys: /ns: {node: {ros__parameters: ...}}
                k = str(key)
                walk(f'{prefix}/{k.strip("/")}' if prefix else k, sub)

    walk('', doc)
    return rules


def _split_rule(text: str, flag: str) -> tuple[str | None, str, str]:
    """'[node:]lhs:=rhs' -> (node, lhs, rhs)."""
    if ':=' not in text:
        raise ArgumentError(f"{flag} rule {text!r} must have the form '[node:]name:=value'")
    lhs, rhs = text.split(':=', 1)
    node = None
    if ':' in lhs:
        node, lhs = lhs.split(':', 1)
    if not lhs:
        raise ArgumentError(f'{flag} rule {text!r} has an empty name')
    return node, lhs, rhs


_IGNORED_FLAGS = {
    '--disable-rosout-logs',
    '--enable-rosout-logs',
    '--disable-stdout-logs',
    '--enable-stdout-logs',
    '--disable-external-lib-logs',
    '--enable-external-lib-logs',
}


def parse_ros_args(argv: Iterable[str] | None) -> RosArguments:
    """Split argv into ROS rules (in order) and the remaining non-ROS arguments."""
    out = RosArguments()
    if not argv:
        return out
    args = list(argv)
    i = 0
    in_ros = False
    while i < len(args):
        a = args[i]
        if a == '--ros-args':
            in_ros = True
            i += 1
            continue
        if not in_ros:
            out.unparsed.append(a)
            i += 1
            continue
        if a == '--':
            in_ros = False
            i += 1
            continue

        def value() -> str:
            if i + 1 >= len(args):
                raise ArgumentError(f"'{a}' needs a value")
            return args[i + 1]

        if a in ('-p', '--param'):
            node, name, text = _split_rule(value(), a)
            try:
                v = load_yaml(text) if text else ''
            except yaml.YAMLError as exc:
                raise ArgumentError(f'cannot parse value of {name!r}: {exc}') from None
            out.params.append(ParamRule(node or '/**', name, _check_value(v, name, a), a))
            i += 2
        elif a == '--params-file':
            out.params.extend(load_params_file(value()))
            i += 2
        elif a in ('-r', '--remap'):
            node, src, dst = _split_rule(value(), a)
            out.remaps.append(RemapRule(node, src, dst))
            i += 2
        elif a == '--log-level':
            text = value()
            if ':=' in text:
                name, level = text.split(':=', 1)
            else:
                name, level = '', text
            out.log_levels[name] = level.upper()
            i += 2
        elif a in ('-e', '--enclave'):
            i += 2
        elif a in _IGNORED_FLAGS:
            i += 1
        else:
            raise ArgumentError(f"unknown ROS argument '{a}'")
    return out


def remove_ros_args(argv: Iterable[str] | None) -> list[str]:
    return parse_ros_args(argv).unparsed


def node_pattern_matches(pattern: str, fqn: str) -> bool:
    if not pattern.startswith('/'):
        pattern = '/' + pattern
    regex = pattern.replace('/*', r'(/\w+)')
    return re.fullmatch(regex, fqn) is not None


def overrides_for(node_fqn: str, sources: Iterable[RosArguments]) -> dict[str, Any]:
    """Parameter overrides that apply to one node, merged as rcl and rclpy merge them.

    rcl parses every params file and ``-p`` rule into one table keyed by the node name *as
    written*, in order of first appearance (rcl_yaml_param_parser reuses an existing key); a
    later value replaces an earlier one within its key. rclpy then applies the keys that match
    the node in table order. So ``plant_sim: {payload_kg: 0.3}`` in one file beats a later
    file's ``/**: {payload_kg: 0.5}`` (``/**`` appeared first), while a later ``plant_sim:``
    entry replaces it. (Measured under ROS 2 Humble: launch_ros writes a launch file's
    ``parameters=[{...}]`` under ``/**``, and config/wrist.yaml's node sections won.)
    """
    table: dict[str, dict[str, Any]] = {}  # insertion order = first appearance of the key
    for src in sources:
        for rule in src.params:
            table.setdefault(rule.node, {})[rule.name] = rule.value
    result: dict[str, Any] = {}
    for key, values in table.items():
        if node_pattern_matches(key, node_fqn):
            result.update(values)
    return result
