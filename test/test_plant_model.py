"""The plant model a params file describes: one reader for sma-wrist diagnose --params-file and the twin monitor."""

from __future__ import annotations

import dataclasses

import pytest
import yaml

from sma_wrist.core.hysteresis.params_file import save_hysteresis
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.plant_model import PlantModelFileError, read_plant_model

PRELOAD_MM = PlantParams().preload_elongation_mm + 0.3  # a chain pre-loaded 0.3 mm more than the built-in's
COULOMB_NM = 0.05  # and more friction than the built-in 0.004 N m


def commissioned(folder, **plant):
    """A wrist_params.yaml as sma-wrist commission hands it over: several nodes, the controllers' first, the model
    files next to it named by relative paths."""
    from sma_wrist.core.hysteresis.default_params import default_sdgpi

    save_hysteresis(folder / 'hysteresis.yaml', default_sdgpi(), {'source': 'built-in'})
    values = {
        'hysteresis_file': 'hysteresis.yaml',
        'thermal_file': '',
        'preload_elongation_mm': PRELOAD_MM,
        'payload_kg': 0.3,
        'model.coulomb_Nm': COULOMB_NM,
        **plant,
    }
    f = folder / 'wrist_params.yaml'
    f.write_text(
        yaml.safe_dump(
            {
                'tem_controller': {'ros__parameters': {'thermal_file': ''}},
                'hysteresis_compensator': {'ros__parameters': {'preload_elongation_mm': 1.0}},
                'hardware_bridge': {'ros__parameters': {'preload_elongation_mm': 1.5, 'hysteresis_file': ''}},
                'plant_sim': {'ros__parameters': values},
            },
            sort_keys=False,
        )
    )
    return f


def test_a_commissioned_file_gives_plant_sims_model_with_paths_relative_to_it(tmp_path, monkeypatch):
    f = commissioned(tmp_path)
    monkeypatch.chdir('/')  # the relative paths are the file's, not the working directory's
    m = read_plant_model(f)
    assert m.node == 'plant_sim'
    assert m.hysteresis_file == str((tmp_path / 'hysteresis.yaml').resolve())
    assert m.thermal_file is None
    assert m.preload_elongation_mm == PRELOAD_MM
    p = m.params()
    assert p.preload_elongation_mm == PRELOAD_MM and p.joint.coulomb_Nm == COULOMB_NM


def test_without_plant_sim_the_bridges_model_is_read(tmp_path):
    f = tmp_path / 'bridge.yaml'
    f.write_text(yaml.safe_dump({'hardware_bridge': {'ros__parameters': {'preload_elongation_mm': 1.7}}}))
    m = read_plant_model(f)
    assert (m.node, m.preload_elongation_mm, m.hysteresis_file) == ('hardware_bridge', 1.7, None)


@pytest.mark.parametrize(
    'doc,named',
    [
        ({'tem_controller': {'ros__parameters': {'thermal_file': ''}}}, 'no plant node section'),
        ({'plant_sim': {'ros__parameters': {'model.coulomb': 0.1}}}, 'has no parameter model.coulomb'),
        ({'plant_sim': {'ros__parameters': {'preload_elongation': 2.0}}}, 'has no parameter preload_elongation'),
        ({'plant_sim': {'ros__parameters': {'hysteresis_file': 'absent.yaml'}}}, 'absent.yaml: no such file'),
        ({'plant_sim': {'ros__parameters': {'model.coulomb_Nm': 5.0}}}, 'coulomb_Nm = 5.0'),
    ],
)
def test_a_file_that_describes_no_usable_plant_is_refused_by_name(tmp_path, doc, named):
    f = tmp_path / 'p.yaml'
    f.write_text(yaml.safe_dump(doc))
    with pytest.raises(PlantModelFileError, match=named):
        read_plant_model(f)


def test_explicit_model_files_replace_the_params_files(tmp_path):
    f = commissioned(tmp_path)
    other = tmp_path / 'other'
    other.mkdir()
    h = commissioned(other).parent / 'hysteresis.yaml'
    assert read_plant_model(f, hysteresis_file=str(h)).hysteresis_file == str(h.resolve())


def test_the_twin_monitor_reads_the_same_model(tmp_path, monkeypatch):
    from sma_wrist.monitor.twin import MonitorInputError, load_model

    f = commissioned(tmp_path)
    monkeypatch.chdir('/')
    model = load_model(params_file=str(f))
    assert model.params.preload_elongation_mm == PRELOAD_MM
    assert model.params.joint == read_plant_model(f).params().joint
    assert model.hysteresis_file == str((tmp_path / 'hysteresis.yaml').resolve())
    assert model.extension == {'coulomb_Nm': COULOMB_NM}
    # a diagnosis' extended_params.yaml: one plant_sim section, a replay-only effect the twin does not simulate
    ext = tmp_path / 'extended_params.yaml'
    ext.write_text(yaml.safe_dump({'plant_sim': {'ros__parameters': {'payload_kg': 0.3, 'model.hyst_lag_s': 2.0}}}))
    model = load_model(params_file=str(ext))
    assert model.extension == {'hyst_lag_s': 2.0}
    assert model.params.joint == PlantParams().joint
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'twin_monitor': {'ros__parameters': {'params_file': 'x'}}}))
    with pytest.raises(MonitorInputError, match='no plant node section'):
        load_model(params_file=str(bad))


@pytest.fixture(scope='module')
def commissioned_wrist_run():
    """30 s of a wrist pre-loaded and rubbing as :func:`commissioned`'s file says (one simulation for the tests)."""
    from sma_wrist.diagnose import testdata as td

    truth = td.simulate(
        'none',
        seed=3,
        duration_s=30.0,
        params={'preload_err_mm': PRELOAD_MM - PlantParams().preload_elongation_mm, 'coulomb_Nm': COULOMB_NM},
    )
    return td.run_from_truth(truth)


def test_diagnose_replays_the_params_files_preload_and_friction(tmp_path, commissioned_wrist_run):
    """A wrist pre-loaded and rubbing as its commissioned file says is clean against that file, and a discrepancy
    against the built-in model; the extended model written carries the file's model."""
    from sma_wrist.diagnose import diagnose_run

    run = commissioned_wrist_run
    f = commissioned(tmp_path)
    cands = ['recalibrate_mechanics', 'friction']
    assert diagnose_run(run, candidates=cands).discrepancy
    res = diagnose_run(run, params_out=tmp_path / 'ext.yaml', candidates=cands, params_file=str(f))
    assert not res.discrepancy, res.summary
    written = read_plant_model(tmp_path / 'ext.yaml')
    expect = dataclasses.replace(read_plant_model(f), source=written.source, payload_kg=run.payload_kg)
    assert written == expect


def test_diagnose_shows_the_replayed_models_values_as_nominal(tmp_path, commissioned_wrist_run):
    """The fitted parameters' nominal is the value of the model replayed: a file's model.coulomb_Nm (0.05) and
    model.viscous_Nms (0.3), not the catalogue's 0.004 and 0.15; an error such as preload_err_mm is 0, relative to
    the file's pre-load, which the report's header names with the file. Here the file says the built-in pre-load,
    0.3 mm less than the wrist's, so the diagnosis names a discrepancy and the report lists its parameters."""
    from sma_wrist.diagnose import diagnose_run

    viscous = 0.3
    f = commissioned(
        tmp_path, preload_elongation_mm=PlantParams().preload_elongation_mm, **{'model.viscous_Nms': viscous}
    )
    res = diagnose_run(
        commissioned_wrist_run,
        report_dir=tmp_path / 'report',
        candidates=['recalibrate_mechanics', 'friction'],
        params_file=str(f),
    )
    assert res.discrepancy and res.parameters, res.summary
    replayed = {'coulomb_Nm': COULOMB_NM, 'viscous_Nms': viscous, 'preload_err_mm': 0.0, 'payload_err_kg': 0.0}
    shown = [res.parameters] + [a['parameters'] for a in res.alternatives]
    nominal = {k: v['nominal'] for params in shown for k, v in params.items()}
    assert nominal == {k: replayed[k] for k in nominal} and {'coulomb_Nm', 'viscous_Nms'} <= set(nominal)
    assert res.to_json()['parameters'] == res.parameters
    report = (tmp_path / 'report' / 'diagnosis.md').read_text()
    header = report.split('## ')[0]
    assert str(f) in header and f'preload_elongation_mm {PlantParams().preload_elongation_mm:g}' in header
    rows = {line.split(' | ')[0].strip('| '): line for line in report.splitlines() if line.startswith('| ')}
    for k in res.parameters:
        assert rows[k].rstrip(' |').endswith(f'{replayed[k]:.5g}'), rows[k]


def test_diagnose_cli_names_a_params_file_without_a_plant(tmp_path, capsys):
    from sma_wrist.cli import main

    f = tmp_path / 'p.yaml'
    f.write_text(yaml.safe_dump({'tem_controller': {'ros__parameters': {}}}))
    assert main(['diagnose', str(tmp_path / 'bag'), '--params-file', str(f)]) == 2
    err = capsys.readouterr().err
    assert 'no plant node section' in err and 'Traceback' not in err


def test_the_monitors_checks_replay_the_params_files_model(tmp_path, commissioned_wrist_run):
    """A check of the same wrist is OK against the file the twin runs, not against the built-in pre-load."""
    from sma_wrist.monitor import MonitorConfig, diagnose_window

    run = commissioned_wrist_run
    f = commissioned(tmp_path)
    config = MonitorConfig(candidates=('recalibrate_mechanics', 'friction'))
    assert diagnose_window(run, 30.0, config).level == 'WARN'
    v = diagnose_window(run, 30.0, config, params_file=str(f))
    assert v.level == 'OK', v.summary


def test_model_files_named_relative_to_the_folder_the_file_was_written_from_are_found(tmp_path, monkeypatch):
    """A params file written into runs/x names its model files runs/x/... (what the nodes, started from that folder,
    look for); the reader finds them there when they are not beside the file under that name."""
    (tmp_path / 'runs' / 'x').mkdir(parents=True)
    f = commissioned(tmp_path / 'runs' / 'x', hysteresis_file='runs/x/hysteresis.yaml')
    monkeypatch.chdir(tmp_path)
    m = read_plant_model(f.relative_to(tmp_path))
    assert m.hysteresis_file == str((tmp_path / 'runs' / 'x' / 'hysteresis.yaml').resolve())
    monkeypatch.chdir('/')
    with pytest.raises(PlantModelFileError, match='no such file'):
        read_plant_model(f)


def test_the_commissioned_params_file_points_the_twin_monitor_at_its_own_model(tmp_path, monkeypatch):
    """sma-wrist commission hands over one file for every node: the twin monitor (run --monitor, monitor:=true)
    watches the wrist as commissioned (plant_sim's model in that file), named by an absolute path."""
    from sma_wrist.commission.run import write_params
    from sma_wrist.monitor.twin import load_model

    (tmp_path / 'out').mkdir()
    monkeypatch.chdir(tmp_path)
    nodes = {'plant_sim': {'preload_elongation_mm': PRELOAD_MM, 'model.coulomb_Nm': COULOMB_NM}}
    f = write_params(tmp_path / 'out' / 'wrist_params.yaml', [], {}, nodes)
    twin = yaml.safe_load(f.read_text())['twin_monitor']['ros__parameters']
    assert twin['params_file'] == str(f.resolve())
    monkeypatch.chdir('/')
    model = load_model(params_file=twin['params_file'])
    assert model.params.preload_elongation_mm == PRELOAD_MM and model.extension == {'coulomb_Nm': COULOMB_NM}
    # a bring-up alone (no model identified) leaves the twin on its defaults
    assert 'twin_monitor' not in yaml.safe_load(write_params(tmp_path / 'b.yaml', [], {}).read_text())


def test_diagnose_cli_names_a_malformed_wire_file_of_the_params_file(tmp_path, capsys):
    from sma_wrist.cli import main

    (tmp_path / 'wire.yaml').write_text('format: sma_wrist.wire\nversion: 1\nform: phase_fraction\nmodel: [1, 2]\n')
    f = tmp_path / 'p.yaml'
    f.write_text(yaml.safe_dump({'plant_sim': {'ros__parameters': {'wire_file': 'wire.yaml'}}}))
    assert main(['diagnose', str(tmp_path / 'bag'), '--params-file', str(f)]) == 2
    err = capsys.readouterr().err
    assert 'wire.yaml' in err and 'model must be a mapping' in err and 'Traceback' not in err
