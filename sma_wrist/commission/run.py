"""The ``sma-wrist commission`` command: bring-up on a port (or the simulated plant), report, params file, JSON.

Exit codes: 0 commissioned (the bring-up passed, the params file is written and verified in closed loop), 3 a
fault found on the device stopped it (wiring, sensor, link; the JSON is printed all the same), 2 bad input (options, params files, a
port that does not open), 130 interrupted (Ctrl-C). In every case the TEMs are left at 0 V and the report holds
what was learnt.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from sma_wrist.commission.bringup import BringUp, BringUpLimits
from sma_wrist.commission.device import PortError, SerialDevice, SimDevice
from sma_wrist.core.errors import ParameterError, SmaWristError
from sma_wrist.core.yaml_file import write_yaml_file
from sma_wrist.hw.calibration import Calibration, Wiring

EXIT_OK, EXIT_BAD_INPUT, EXIT_FAULT, EXIT_INTERRUPTED = 0, 2, 3, 130
BRIDGE = 'hardware_bridge'
TWIN = 'twin_monitor'
PARAMS_FILE = 'wrist_params.yaml'


def bridge_values(params_files: Sequence[str | Path] = ()) -> dict[str, Any]:
    """hardware_bridge's parameter values after config/wrist.yaml and ``params_files`` (as the graph would get
    them); ParameterError for a missing file, a misspelt key or a value the bridge refuses."""
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.nodes.common import refuse_undeclared
    from sma_wrist.nodes.hardware_bridge import HardwareBridge
    from sma_wrist.runtime.arguments import load_params_file
    from sma_wrist.share import share_path

    values = {p.name: p.default for p in HardwareBridge.PARAMS}
    files = [share_path('config/wrist.yaml'), *params_files]
    for f in params_files:
        if not Path(f).is_file():
            raise ParameterError(f'params file {f}: no such file')
    refuse_undeclared(params_files, {BRIDGE: set(values)})
    for f in files:
        for rule in load_params_file(f):
            if rule.node.strip('/') in ('**', '*', BRIDGE) and rule.name in values:
                values[rule.name] = rule.value
    wiring_problem = None
    try:
        wiring_problem = Wiring.from_params(values).problem()
    except (TypeError, ValueError):
        wiring_problem = 'calibration.tem_sign, tem_channel_map and thermocouple_map must be lists of integers'
    if wiring_problem:
        raise ParameterError(f'{BRIDGE}: {wiring_problem}')
    if values['calibration.angle_gain_rad_per_count'] == 0:
        raise ParameterError(f'{BRIDGE}: calibration.angle_gain_rad_per_count must not be 0')
    return values


def calibration_of(values: dict[str, Any]) -> Calibration:
    """The bridge's calibration from its parameter values (the bridge's own map, one place)."""
    from sma_wrist.nodes.hardware_bridge import HardwareBridge

    return HardwareBridge._calibration(values)


def write_params(
    path: Path,
    params_files: Sequence[str | Path],
    bridge: dict[str, Any],
    nodes: dict[str, dict[str, Any]] | None = None,
) -> Path:
    """``params_files`` merged (later ones win) with ``nodes`` (the identified model's parameters per node) and
    ``bridge`` set under hardware_bridge: the file to hand over."""
    import yaml

    doc: dict[str, Any] = {}
    for f in params_files:
        for node, body in (yaml.safe_load(Path(f).read_text()) or {}).items():
            doc.setdefault(node, {'ros__parameters': {}})['ros__parameters'].update(
                copy.deepcopy((body or {}).get('ros__parameters', {}))
            )
    nodes = dict(nodes or {})
    if nodes:  # the twin monitor watches the wrist as commissioned (plant_sim's model of this file), not the built-in
        nodes.setdefault(TWIN, {})['params_file'] = str(path.resolve())
    for node, values in {**nodes, BRIDGE: {**nodes.get(BRIDGE, {}), **bridge}}.items():
        key = next((k for k in doc if k.strip('/') == node), node)
        doc.setdefault(key, {'ros__parameters': {}})['ros__parameters'].update(values)
    comment = (
        'sma_wrist parameters of a commissioned wrist (sma-wrist commission; doc/howto/commission.md).\n'
        'hardware_bridge: the wiring and the angle calibration the bring-up measured'
        + ('; every node: the model identified from the excitation.' if nodes else '.')
    )
    return write_yaml_file(path, doc, comment, flow_lists=True)


def commission(
    out: str | Path,
    device: Any,
    *,
    params_files: Sequence[str | Path] = (),
    payload_kg: float | None = None,
    accept_fixes: bool = False,
    limits: BringUpLimits | None = None,
    progress: Callable[[str], None] | None = None,
    port: str | None = None,
    bring_up_only: bool = False,
    excite_budget_s: float = 600.0,
    verification: Any = None,
) -> dict[str, Any]:
    """Bring the wrist on ``device`` (SerialDevice or SimDevice) up, then (unless ``bring_up_only``) excite it for
    at most ``excite_budget_s`` of device time and identify its model; write the report (and, when it passes, the
    params file) into ``out``; return the result (JSON-ready). KeyboardInterrupt is caught: status 'interrupted'.
    PortError (bad input) propagates after the report is written. ``verification``
    (:class:`sma_wrist.commission.verify.VerifyOptions`): then verify the params file in closed loop."""
    from sma_wrist.commission.report import write_report

    # absolute, so that the params file names its model files for nodes started from any folder
    out = Path(out).expanduser().resolve()
    values = bridge_values(params_files)
    lim = limits or BringUpLimits()
    problem = lim.problem()
    if problem:
        raise ParameterError(problem)
    out.mkdir(parents=True, exist_ok=True)
    bring = BringUp(device, calibration_of(values), Wiring.from_params(values), lim, accept_fixes, progress)
    status, message, ident = 'fault', '', None
    try:
        try:
            device.open()
            status = 'commissioned' if bring.run() == 'passed' else 'fault'
            if status == 'commissioned' and not bring_up_only:
                status, ident = _identify(bring, out, payload_kg, excite_budget_s)
        except PortError as e:
            status, message = 'bad_port', str(e)
            raise
        except KeyboardInterrupt:
            status = 'interrupted'
            message = f'interrupted during the {bring.step or "link"} step: TEMs off; what was measured is kept'
        finally:
            device.close()  # TEMs off again, the port closed (also after a failed open or Ctrl-C while opening)
    finally:
        result = _result(bring, status, message, port or getattr(device, 'port', ''), lim)
        if status == 'commissioned':
            bridge = {
                **bring.wiring.params(),
                'calibration.angle_gain_rad_per_count': bring.cal.angle_gain_rad_per_count,
                'calibration.angle_offset_rad': bring.cal.angle_offset_rad,
            }
            if port:
                bridge['port'] = port
            if payload_kg is not None:
                bridge['payload_kg'] = float(payload_kg)
            result['bridge_params'] = bridge
            nodes = ident.node_params if ident else None
            result['params_file'] = str(write_params(out / PARAMS_FILE, params_files, bridge, nodes))
        if ident is not None:
            result['identified'] = ident.identified
            result['warnings'] += ident.warnings
            result['figures'] = ident.figures
        result['report'] = str(write_report(out, result, bring))
    # ---- verification: the closed loop with the params file handed over (sma_wrist/commission/verify.py)
    result.setdefault('identified', {})
    result['verification'] = None
    if verification is not None and result['status'] == 'commissioned':
        from sma_wrist.commission.verify import run_verification

        run_verification(result, out, device, verification, progress, bring, ident.refinement if ident else None)
    # ---- end of verification
    return result


def _identify(bring: BringUp, out: Path, payload_kg: float | None, budget_s: float) -> tuple[str, Any]:
    """The excitation and identification after a passed bring-up: ('commissioned', Identified) or ('fault', None)
    with the fault in ``bring.faults`` (the TEMs off)."""
    from sma_wrist.commission.bringup import Stop
    from sma_wrist.commission.detect import Fault
    from sma_wrist.commission.device import DeviceLost
    from sma_wrist.commission.excite import excite
    from sma_wrist.commission.identification import IdentificationError, identify_wrist

    try:
        excite(bring, budget_s)
    except Stop as e:
        bring.faults.append(e.fault)
        return 'fault', None
    except DeviceLost as e:
        fix = "check the cable, the port and the device's supply; then run commissioning again"
        bring.faults.append(Fault('link_lost', None, f'{e} during the excitation', fix))
        return 'fault', None
    bring.off()
    bring.step = 'identify'
    bring.progress('identify')
    try:
        return 'commissioned', identify_wrist(bring, out, payload_kg)
    except (IdentificationError, SmaWristError) as e:  # the data cannot identify a part (e.g. a thermal fit refused)
        bring.faults.append(Fault('not_identified', None, str(e), 'see the excitation plot in the report'))
        return 'fault', None
    finally:
        bring.step = ''


def _result(bring: BringUp, status: str, message: str, port: str, lim: BringUpLimits) -> dict[str, Any]:
    return {
        'status': status,
        'message': message,
        'port': port,
        'faults': [f.to_json() for f in bring.faults],
        'warnings': list(bring.warnings),
        'steps': bring.steps,
        'wiring': bring.wiring.params(),
        'bridge_params': {},
        'params_file': None,
        'report': None,
        'device_time_s': round(bring.t, 3),
        'max_drive_V': round(bring.max_drive_sent_V, 3),
        'limits': {
            'max_drive_V': lim.max_drive_V,
            'pulse_V': lim.pulse_V,
            'pulse_s': lim.pulse_s,
            'heat_V': lim.heat_V,
            'cool_V': lim.cool_V,
            'max_muscle_C': lim.max_muscle_C,
        },
    }


def exit_code(result: dict[str, Any]) -> int:
    status = result['status']
    if status == 'commissioned':
        return EXIT_OK
    if status == 'interrupted':
        return EXIT_INTERRUPTED
    if status == 'bad_port':
        return EXIT_BAD_INPUT
    return EXIT_FAULT


def sim_device(params_files: Sequence[str | Path], payload_kg: float, seed: int) -> SimDevice:
    """The simulated plant of ``params_files`` (as plant_sim would build it) behind the emulated device."""
    from sma_wrist.hw.emulator import EmulatorConfig

    base = None
    if params_files:
        from sma_wrist.sweep.graph_params import plant_params

        base = plant_params(params_files)
    return SimDevice(EmulatorConfig(payload_kg=payload_kg, seed=seed, base=base))


def _print_text(result: dict[str, Any]) -> None:
    print(
        f'commission: {result["status"]} after {result["device_time_s"]:.1f} s of device time '
        f'(largest drive {result["max_drive_V"]:g} V)'
    )
    if result['message']:
        print(result['message'])
    for f in result['faults']:
        print(
            f'{"FIXED" if f["fixed"] else "FAULT"} {f["kind"]}'
            + (f' (channel {f["channel"]})' if f['channel'] else '')
            + f': {f["message"]}\n  fix: {f["fix"]}'
        )
    for w in result['warnings']:
        print(f'warning: {w}')
    if result['params_file']:
        print(f'params file: {result["params_file"]}')
    print(f'report: {result["report"]}')


def verify_options(a: argparse.Namespace) -> Any:
    """The verification the command line asks for (None: ``--verify-s 0``); ValueError naming a bad option."""
    from sma_wrist.commission.verify import VerifyOptions, controllers_of

    if not (math.isfinite(a.verify_s) and a.verify_s >= 0):
        raise ValueError(f'--verify-s {a.verify_s!r} must be a finite number >= 0 (0: no verification)')
    if a.verify_s == 0:
        return None
    ctrls = None if a.controllers is None else tuple(controllers_of(a.controllers))
    return VerifyOptions(controllers=ctrls, duration_s=a.verify_s)


def run_cli(a: argparse.Namespace) -> int:
    """``sma-wrist commission``; errors of the user's input are 'error: ...' with exit 2."""
    from sma_wrist.contract import PAYLOAD_RANGE_KG

    if (a.hardware is None) == (not a.sim):
        print('error: give either --hardware PORT or --sim', file=sys.stderr)
        return EXIT_BAD_INPUT
    payload = a.payload_kg
    if payload is not None and not PAYLOAD_RANGE_KG[0] <= payload <= PAYLOAD_RANGE_KG[1]:
        print(
            f'error: --payload-kg {payload:g} is outside [{PAYLOAD_RANGE_KG[0]:g}, {PAYLOAD_RANGE_KG[1]:g}] kg',
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    if not (math.isfinite(a.stall_s) and a.stall_s > 0):
        print(f'error: --stall-s {a.stall_s!r} must be a finite number > 0', file=sys.stderr)
        return EXIT_BAD_INPUT
    try:
        lim = BringUpLimits(heat_V=a.heat_V, max_muscle_C=a.max_muscle_C)
        device = (
            sim_device(a.params_file, 0.3 if payload is None else payload, a.seed)
            if a.sim
            else SerialDevice(a.hardware, a.baud_rate, stall_s=a.stall_s)
        )
        progress = None if a.json else (lambda step: print(f'step: {step}', file=sys.stderr, flush=True))
        verification = verify_options(a)
        result = commission(
            a.out,
            device,
            params_files=a.params_file,
            payload_kg=payload,
            accept_fixes=a.accept_fixes,
            limits=lim,
            progress=progress,
            port=a.hardware,
            bring_up_only=a.bring_up_only,
            verification=None if a.bring_up_only else verification,
        )
    except PortError as e:
        print(f'error: {e} (report: {Path(a.out) / "commission.md"})', file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SmaWristError, ValueError) as e:
        print(f'error: {e}', file=sys.stderr)
        return EXIT_BAD_INPUT
    if a.json:
        print(json.dumps(result, indent=2))
    else:
        _print_text(result)
        if result['verification']:
            from sma_wrist.commission.verify import text_lines

            print('\n'.join(text_lines(result['verification'])))
    if result['status'] == 'interrupted':
        print(f'interrupted: TEMs off; report so far: {result["report"]}', file=sys.stderr)
    return exit_code(result)


__all__ = [
    'commission',
    'bridge_values',
    'write_params',
    'run_cli',
    'exit_code',
    'sim_device',
    'EXIT_OK',
    'EXIT_BAD_INPUT',
    'EXIT_FAULT',
    'EXIT_INTERRUPTED',
]
