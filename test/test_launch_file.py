"""The launch files run on the embedded launcher, and a required node's exit ends the launch."""

from __future__ import annotations

from pathlib import Path

import pytest

from sma_wrist.runtime.launch_file import LaunchFileError, run_launch_file
from sma_wrist.share import share_path


def _launch(name: str) -> str:
    return str(share_path(f'launch/{name}'))


@pytest.mark.parametrize(
    'launch, source, arguments',
    [
        ('wrist_sim.launch.py', 'plant_sim', {'payload_kg': 5.0}),
        ('wrist_hw.launch.py', 'hardware_bridge', {'payload_kg': 5.0, 'port': '/nonexistent/wrist'}),
    ],
)
def test_a_refusing_plant_or_bridge_shuts_the_launch_down_with_the_reason_and_exit_code_1(launch, source, arguments):
    """The launch shut itself down, but ros2 launch exited 0, so a script could not tell a refused start from a
    normal end. The required node's non-zero exit now raises in its on_exit action: launch's LaunchService.run
    returns 1 for that (Humble and Jazzy), with its "Caught exception in launch" message."""
    printed: list[str] = []
    r = run_launch_file(_launch(launch), arguments, 2.0, print_fn=printed.append)
    assert r.reason == 'shutdown' and r.return_code == 1
    want = f'Caught exception in launch (see debug for traceback): {source} exited with code 2: the graph has no '
    assert r.shutdown_reason.startswith(want) and 'no /clock' in r.shutdown_reason
    assert r.exits == {source: 2}
    assert r.run is None  # nothing was left spinning without its clock
    assert 'trajectory_generator' in r.started  # the others were up, as under ros2 launch
    assert any('invalid parameter payload_kg' in line for line in printed)
    assert f'[ERROR] [launch]: {r.shutdown_reason}' in printed


def test_nominal_launch_runs_every_node_of_the_graph_on_its_clock():
    r = run_launch_file(_launch('wrist_sim.launch.py'), {'controller': 'pid'}, 0.3)
    assert r.reason == 'time' and r.exits == {} and r.return_code == 0
    assert r.started == ['plant_sim', 'trajectory_generator', 'adaptive_controller', 'tem_controller']
    assert r.run.sim_ns >= 300_000_000


def test_launch_argument_choices_are_enforced():
    with pytest.raises(LaunchFileError, match="Argument 'controller' provided value 'bogus' is not valid"):
        run_launch_file(_launch('wrist_sim.launch.py'), {'controller': 'bogus'}, 0.1)


def test_a_params_files_payload_stands_unless_payload_kg_is_given(tmp_path, capfd):
    """payload_kg:= defaulted to 0.3 and was written over every params file, so a params_file:= with its own
    payload_kg ran 0.3 kg in silence (as `sma-wrist run --params-file` did). Its default is now empty: the params
    files' payload stands; payload_kg:= given still wins."""
    f = tmp_path / 'mine.yaml'
    f.write_text('plant_sim:\n  ros__parameters:\n    payload_kg: 0.6\n')
    for arguments, kg in (
        ({'params_file': str(f)}, '0.6'),
        ({'params_file': str(f), 'payload_kg': '0.1'}, '0.1'),
        ({}, '0.3'),
    ):
        capfd.readouterr()
        run_launch_file(_launch('wrist_sim.launch.py'), {'controller': 'pid', **arguments}, 0.1)
        out = capfd.readouterr()
        assert f'plant_sim: payload {kg} kg' in out.out + out.err, arguments  # plant_sim's start-up line


def test_a_required_nodes_exit_during_a_shutdown_is_no_fault(monkeypatch):
    """A user's Ctrl-C ends plant_sim with the rest: the launch is already shutting down, and its exit must not be
    logged as "the graph has no plant" (it was, under Humble and Jazzy). Outside a shutdown it still is."""
    import sys

    from sma_wrist.launch_support import REQUIRED_EXIT_REASONS, on_exit_actions
    from sma_wrist.runtime import launch_file as lf

    monkeypatch.setitem(sys.modules, 'launch', lf)  # the launch API subset the embedded launcher provides
    monkeypatch.setitem(sys.modules, 'launch.actions', lf)
    (action,) = on_exit_actions('plant_sim')
    for shutting_down, code, want in (
        (True, 2, []),
        (True, 0, []),
        (False, 0, [REQUIRED_EXIT_REASONS['plant_sim']]),
        (False, 2, []),
    ):
        ctx = lf.LaunchContext({})
        ctx.is_shutdown = shutting_down
        result = lf.LaunchResult('time')
        lf._on_exit([action], ctx, result, print_fn=lambda s: None, event=lf.ProcessExited('plant_sim-1', code))
        assert result.log == want and (result.reason == 'shutdown') is not shutting_down
        # a clean exit (0) ends the launch with 0, a failed one with 1: never during a shutdown
        assert result.return_code == (0 if shutting_down or code == 0 else 1)
    assert on_exit_actions('tem_controller') is None


@pytest.mark.parametrize('launch, extra', [('wrist_sim.launch.py', {}), ('wrist_hw.launch.py', {'port': '/dev/x'})])
def test_each_node_gets_config_wrist_yaml_once_and_a_params_file_after_it(launch, extra, tmp_path):
    """params_file:= defaulted to config/wrist.yaml, so every node's command line carried that file twice."""
    from sma_wrist.runtime import launch_file as lf

    mine = tmp_path / 'mine.yaml'
    mine.write_text('plant_sim:\n  ros__parameters:\n    payload_kg: 0.6\n')
    defaults = str(share_path('config/wrist.yaml'))
    for arguments, files in (({}, [defaults]), ({'params_file': str(mine)}, [defaults, str(mine)])):
        with lf._LaunchModules():
            context, nodes = lf._configure(lf._load(Path(_launch(launch))), {**extra, **arguments})
        assert len(nodes) >= 4
        for node in nodes:
            given = [lf._perform(p, context) for p in node.parameters]
            assert given[:-1] == files, (node.name, given)  # the last: the node's own overrides
            assert Path(given[-1]).name.startswith(node.name)
