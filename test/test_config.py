"""Params files and the topic contract agree with the code (one source of truth)."""

from __future__ import annotations

import ast
import os
from pathlib import Path

import pytest
import yaml

from sma_wrist.contract import load_contract

ROOT = Path(__file__).resolve().parent.parent
NODE_CLASSES = {
    'plant_sim': ('sma_wrist.nodes.plant_sim', 'PlantSim'),
    'hardware_bridge': ('sma_wrist.nodes.hardware_bridge', 'HardwareBridge'),
    'trajectory_generator': ('sma_wrist.nodes.trajectory_generator', 'TrajectoryGenerator'),
    'adaptive_controller': ('sma_wrist.nodes.adaptive_controller', 'AdaptiveController'),
    'hysteresis_compensator': ('sma_wrist.nodes.hysteresis_compensator', 'HysteresisCompensator'),
    'tem_controller': ('sma_wrist.nodes.tem_controller', 'TemController'),
    'twin_monitor': ('sma_wrist.nodes.twin_monitor', 'TwinMonitor'),
}


def _declared(node: str) -> set[str]:
    import importlib

    mod, cls = NODE_CLASSES[node]
    return {p.name for p in getattr(importlib.import_module(mod), cls).PARAMS} | {'use_sim_time'}


def _flat_keys(tree: dict, prefix: str = '') -> list[str]:
    """Parameter names of a params-file map: nested maps are dotted names, as rcl reads them."""
    return [
        k
        for key, sub in tree.items()
        for k in (_flat_keys(sub, f'{prefix}{key}.') if isinstance(sub, dict) else [f'{prefix}{key}'])
    ]


@pytest.mark.parametrize('path', sorted((ROOT / 'config').glob('*.yaml')), ids=lambda p: p.name)
def test_every_params_file_key_is_a_declared_parameter(path):
    tree = yaml.safe_load(path.read_text())
    for node, body in tree.items():
        assert set(body) == {'ros__parameters'}, f'{path.name}: {node} must hold only ros__parameters'
        if node == '/**' or node not in NODE_CLASSES:
            continue
        unknown = set(_flat_keys(body['ros__parameters'])) - _declared(node)
        assert not unknown, f'{path.name}: {node} has undeclared parameters {sorted(unknown)} (typo?)'


def test_every_parameter_has_a_description_and_numbers_a_range():
    import importlib

    for node, (mod, cls) in NODE_CLASSES.items():
        for p in getattr(importlib.import_module(mod), cls).PARAMS:
            assert p.description, f'{node}.{p.name} has no description'
            if isinstance(p.default, float):
                assert p.range is not None, f'{node}.{p.name} has no range'
                assert p.range[0] <= p.default <= p.range[1], f'{node}.{p.name} default outside its range'


def _topic_like(text: str) -> bool:
    """A wrist topic name; prose that starts with one (a node's "waiting for ..." line) has spaces, which no ROS name
    has."""
    return text.startswith('/wrist/') and ' ' not in text


def test_contract_topics_are_the_ones_the_nodes_use():
    """Every topic string in a node module is in the contract, and every contract topic has a node."""
    contract = load_contract()
    used = set()
    for f in (ROOT / 'sma_wrist' / 'nodes').glob('*.py'):
        tree = ast.parse(f.read_text())
        inside_fstrings = {id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values}
        for node in ast.walk(tree):
            if id(node) in inside_fstrings:
                continue
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and _topic_like(node.value):
                used.add(node.value)
            if isinstance(node, ast.JoinedStr):
                text = ''.join(v.value if isinstance(v, ast.Constant) else '{}' for v in node.values)
                if text.startswith('/wrist/'):
                    used |= {text.replace('{}', str(i)) for i in (1, 2)}
    assert used <= set(contract.topics), sorted(used - set(contract.topics))
    assert {t for t in contract.topics if t.startswith('/wrist/')} <= used


def test_setup_installs_every_node_and_the_data_files():
    text = (ROOT / 'setup.py').read_text()
    for node in NODE_CLASSES:
        assert f"'{node}': 'sma_wrist.nodes.{node}:main'" in text
    for d in ('launch', 'config', 'msg_defs'):
        assert f"'/{d}'" in text


def test_launch_overrides_written_under_the_node_name_beat_config_wrist_yaml():
    """What the launch files do for controller:= / payload_kg:= (sma_wrist.launch_support): a
    ``/**`` override would lose to wrist.yaml's own node sections (rcl's first-appearance order)."""
    import rclpy

    from sma_wrist.launch_support import node_params_file
    from sma_wrist.nodes.plant_sim import PlantSim
    from sma_wrist.runtime.launch import Runtime
    from sma_wrist.share import share_path

    path = node_params_file('plant_sim', {'payload_kg': 0.7, 'use_sim_time': False})
    try:
        with Runtime(
            ['--ros-args', '--params-file', str(share_path('config/wrist.yaml')), '--params-file', path]
        ) as rt:
            assert rt.add(PlantSim).get_parameter('payload_kg').value == 0.7
        wild = node_params_file('/**', {'payload_kg': 0.7})
        with Runtime(
            ['--ros-args', '--params-file', str(share_path('config/wrist.yaml')), '--params-file', wild]
        ) as rt:
            assert rt.add(PlantSim).get_parameter('payload_kg').value == 0.3  # the trap
    finally:
        rclpy.try_shutdown()


def test_launch_params_files_are_removed_when_the_launch_process_exits(tmp_path):
    """Each launch wrote a file per node into the temporary folder and left it there (hundreds
    after a day of runs); they now live in one folder per launch process, removed at its exit
    (a forked child that exits normally keeps the parent's)."""
    import subprocess
    import sys

    code = (
        'import os, sys\n'
        'from sma_wrist.launch_support import node_params_file\n'
        'paths = [node_params_file(n, {"payload_kg": 0.5}) for n in ("plant_sim", "/**")]\n'
        'assert all(os.path.isfile(p) for p in paths)\n'
        'pid = os.fork()\n'
        'if pid == 0:\n'
        '    sys.exit(0)\n'
        'os.waitpid(pid, 0)\n'
        'assert all(os.path.isfile(p) for p in paths), "a child removed the parent\'s files"\n'
        'print("\\n".join(paths))\n'
    )
    env = {**os.environ, 'TMPDIR': str(tmp_path)}
    r = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 0, r.stderr
    paths = r.stdout.split()
    assert len(paths) == 2 and all(p.startswith(str(tmp_path)) for p in paths)
    assert not any(os.path.exists(p) for p in paths)
    assert list(tmp_path.iterdir()) == []


def test_every_adaptive_controller_parameter_says_what_it_is():
    """`ros2 param describe` on the dataclass-derived parameters (found generic under Humble)."""
    from sma_wrist.nodes.adaptive_controller import FIELD_DOCS, AdaptiveController

    generic = [p.name for p in AdaptiveController.PARAMS if 'sma_wrist.core)' in p.description]
    assert generic == []
    assert all(doc[0] for doc in FIELD_DOCS.values())


def test_adaptive_controller_numeric_parameters_have_real_ranges():
    """Every numeric gain/limit has a range a user can read and the descriptor enforces (no
    +-1e9 placeholders), the tuned defaults and the Table 6.1 params file sit inside it, and a
    value beyond it is refused at run time with the range in the reason."""
    from rclpy.parameter import Parameter

    from sma_wrist.nodes.adaptive_controller import AdaptiveController
    from sma_wrist.runtime.launch import Runtime

    numeric = [p for p in AdaptiveController.PARAMS if isinstance(p.default, float)]
    assert len(numeric) >= 25
    table = yaml.safe_load((ROOT / 'config' / 'paper_table_6_1.yaml').read_text())
    table = table['adaptive_controller']['ros__parameters']
    for p in numeric:
        lo, hi = p.range
        assert -1e4 <= lo < hi <= 1e4, (p.name, p.range)
        assert lo <= p.default <= hi, (p.name, p.default, p.range)
        if p.name in table:
            assert lo <= table[p.name] <= hi, (p.name, table[p.name])
    with Runtime() as rt:
        node = rt.add(AdaptiveController)
        (res,) = node.set_parameters([Parameter('adaptive.c1', value=6000.0)])
        (ok,) = node.set_parameters([Parameter('adaptive.c1', value=600.0)])
    assert not res.successful and '5000' in res.reason
    assert ok.successful and node.law.params.adaptive.c1 == 600.0


def test_run_hint_names_a_parameter_its_params_file_holds(capsys):
    """The hint `sma-wrist run` ends with sends the user to a node's section of config/wrist.yaml for an example
    parameter: that section must hold it (a user without ROS 2 has no `ros2 param describe` to find it)."""
    import re

    from sma_wrist.cli import _print_next

    _print_next('runs/x', None)
    hint = capsys.readouterr().out
    m = re.search(r"config/wrist\.yaml, e\.g\. (\w+)'s ([\w.]+)", hint)
    assert m, hint
    node, name = m.groups()
    section = yaml.safe_load((ROOT / 'config' / 'wrist.yaml').read_text())[node]['ros__parameters']
    assert name in _flat_keys(section), f'the run hint names {node}.{name}, which config/wrist.yaml does not hold'
