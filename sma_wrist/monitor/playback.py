"""``sma-wrist monitor BAG``: the live monitor on a recorded bag, played through as if live.

The bag's messages are fed to :class:`sma_wrist.monitor.Monitor` in the order they arrived (measurements and the
drive the device read back at their header stamps, commands at their log time, a measurement before the command
answering it), and every
``check_period_s`` of bag time the check runs, in line (no wall clock involved: the verdicts are those a live
monitor would have published, whatever the speed of the machine). Prints the timeline of verdicts; ``--json`` one
object (doc/howto/monitor.md).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.contract import ContractError, Recording
from sma_wrist.core.errors import SmaWristError
from sma_wrist.diagnose.data import (
    DRIVE_TOPIC,
    FACE_TOPICS,
    TOPICS,
    DiagnoseInputError,
    _series,
    drive_series,
    face_series,
)
from sma_wrist.monitor import Monitor, MonitorConfig, MonitorInputError, Verdict, write_history

KINDS = {'u1': 'float', 'u2': 'float', 'T1': 'temperature', 'T2': 'temperature', 'joint': 'joint', 'payload': 'float'}


def _bag_series(
    path: str | Path, recording: Recording, warnings: list[str]
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{key of TOPICS: (t [s], values)} of the bag, cleaned as the diagnosis cleans them, with the drive the device
    read back ('a1', 'a2') and the exchanger faces ('F1', 'F2') where the bag has them."""
    from sma_wrist.bag import BagError, read_bag

    p = Path(path)
    if not p.exists():
        raise MonitorInputError(
            f'{p}: no such bag (need a rosbag2 directory with metadata.yaml and .mcap, or an '
            f'.mcap file, recorded per msg_defs/topics.yaml)'
        )
    try:
        data = read_bag(p, recording.recorded([*TOPICS.values(), DRIVE_TOPIC, *FACE_TOPICS]))
    except BagError as exc:
        if not exc.salvaged:
            raise MonitorInputError(f'{p}: cannot read the bag: {exc.problem}') from None
        warnings.append(f'bag damaged ({exc.problem}); monitoring the messages that could be salvaged')
        data = exc.salvaged
    except Exception as exc:  # noqa: BLE001 - anything the bag reader raises
        raise MonitorInputError(f'{p}: cannot read the bag: {type(exc).__name__}: {exc}') from None
    data = recording.as_contract(data)
    series = {}
    for key, topic in TOPICS.items():
        if topic in data and len(data[topic][1]):
            try:
                series[key] = _series(topic, data[topic][0], data[topic][1], KINDS[key], warnings, recording.joint)
            except (ContractError, AttributeError, TypeError, ValueError) as exc:
                raise MonitorInputError(
                    f'{topic}: unexpected message content ({exc}); the contract type is required (msg_defs/topics.yaml)'
                ) from None
    try:
        applied = drive_series(data, warnings)
    except DiagnoseInputError as exc:
        raise MonitorInputError(str(exc)) from None
    for i, k in enumerate(('u1', 'u2'), 1):
        if applied is not None and applied[k][0].size:
            series[f'a{i}'] = applied[k]
    for i, f in enumerate(face_series(data, warnings) or (), 1):
        if f[0].size:
            series[f'F{i}'] = f
    return series


def _events(
    series: dict[str, tuple[np.ndarray, np.ndarray]], p: str, warnings: list[str]
) -> tuple[list[tuple[float, int, str, float]], float | None]:
    """(time-ordered events (t, order, key, value), first payload); MonitorInputError naming what is missing
    and how to record it."""
    record = (
        'record them with the graph running: ros2 bag record '
        + ' '.join(TOPICS[k] for k in ('u1', 'u2', 'T1', 'T2', 'joint', 'payload'))
        + ' (or sma-wrist run --bag DIR); a bag '
        'that names them otherwise: --topic CONTRACT=RECORDED'
    )
    no_u = [TOPICS[f'u{i}'] for i in (1, 2) if f'u{i}' not in series and f'a{i}' not in series]
    if no_u:
        raise MonitorInputError(
            f'{p}: no {" / ".join(no_u)} (std_msgs/Float64, V) nor the drive read back on {DRIVE_TOPIC}: the monitor '
            f'runs the model on the TEM drive and has nothing to compare without it; {record}'
        )
    if not (('T1' in series and 'T2' in series) or 'joint' in series):
        raise MonitorInputError(
            f'{p}: neither the muscle temperatures {TOPICS["T1"]}, {TOPICS["T2"]} '
            f'(sensor_msgs/Temperature, degC) nor the angle {TOPICS["joint"]} '
            f'(sensor_msgs/JointState, rad): nothing to compare the model with; {record}'
        )
    missing = [TOPICS[k] for k in ('T1', 'T2', 'joint', 'payload') if k not in series]
    if missing:
        warnings.append(f'missing topic(s) {", ".join(missing)}: only what the rest allows is checked; {record}')
    payload = float(series['payload'][1][0]) if 'payload' in series else None
    ev: list[tuple[float, int, str, float]] = []
    for key, (t, v) in series.items():
        if key == 'payload':
            continue
        order = 1 if key[0] in 'ua' else 0  # a measurement before the command (drive) that answers it (holds after it)
        ev.extend(zip(t.tolist(), [order] * t.size, [key] * t.size, v.tolist()))
    ev.sort(key=lambda e: (e[0], e[1]))
    return ev, payload


def monitor_bag(
    path: str | Path,
    config: MonitorConfig | None = None,
    recording: Recording | None = None,
    on_verdict: Callable[[Verdict], None] | None = None,
) -> dict[str, Any]:
    """Play the bag through a :class:`Monitor`; the verdicts in bag time (s from the bag's first sample).

    Returns ``{verdicts, episodes, onset_s, warnings, duration_s, checks, check_cpu_s, wall_s, model}``;
    raises MonitorInputError for unusable input."""
    wall0 = time.perf_counter()
    warnings: list[str] = []
    mon = Monitor(config)
    series = _bag_series(path, recording or Recording(), warnings)
    return _play(mon, series, str(path), warnings, wall0, on_verdict)


def monitor_run(run: Any, config: MonitorConfig | None = None) -> dict[str, Any]:
    """The same on an aligned Run (sma_wrist.diagnose.data.Run, e.g. one the effect generator rewrote): its
    samples are the messages, stamped on its grid (the benchmark's path; the bag's adds reading it)."""
    wall0 = time.perf_counter()
    mon = Monitor(config)
    series = {
        'u1': (run.t, run.u[:, 0]),
        'u2': (run.t, run.u[:, 1]),
        'T1': (run.t, run.T[:, 0]),
        'T2': (run.t, run.T[:, 1]),
        'joint': (run.t, run.q),
        'payload': (run.t[:1], np.array([run.payload_kg])),
    }
    return _play(mon, series, run.source, list(run.warnings), wall0, None)


def _play(
    mon: Monitor,
    series: dict[str, tuple[np.ndarray, np.ndarray]],
    p: str,
    warnings: list[str],
    wall0: float,
    on_verdict: Callable[[Verdict], None] | None,
) -> dict[str, Any]:
    events, payload = _events(series, p, warnings)
    t0 = events[0][0]
    mon.payload(payload if payload is not None else 0.3)
    if payload is None:
        warnings.append('/wrist/payload missing: the twin carries the plant default 0.3 kg')
    feed = {
        'u1': lambda t, x: mon.command(1, t, x),
        'u2': lambda t, x: mon.command(2, t, x),
        'a1': lambda t, x: mon.drive(1, t, x),
        'a2': lambda t, x: mon.drive(2, t, x),
        'F1': lambda t, x: mon.face(1, t, x),
        'F2': lambda t, x: mon.face(2, t, x),
        'T1': lambda t, x: mon.temperature(1, t, x),
        'T2': lambda t, x: mon.temperature(2, t, x),
        'joint': mon.angle,
    }
    for t, _, key, x in events:
        t -= t0
        if mon.due(t):
            v = mon.check(t)
            if on_verdict is not None:
                on_verdict(v)
        feed[key](t, x)
    episodes = mon.episodes()
    onset: dict[str, float] = {}
    for e in episodes:
        for c in e['causes']:
            onset.setdefault(c, e['onset_s'])
    cpu = [v.check_cpu_s for v in mon.history]
    return {
        'verdicts': [v.to_json() for v in mon.history],
        'episodes': episodes,
        'onset_s': onset,
        'warnings': warnings,
        'duration_s': events[-1][0] - t0,
        'checks': len(mon.history),
        'check_cpu_s': float(np.mean(cpu)) if cpu else 0.0,
        'model': mon.model.description,
        'wall_s': time.perf_counter() - wall0,
        '_monitor': mon,
    }


def config_from_args(a: argparse.Namespace) -> MonitorConfig:
    cands = tuple(a.candidates.split(',')) if a.candidates else None
    return MonitorConfig(
        window_s=a.window_s,
        settle_s=a.settle_s,
        check_period_s=a.check_period_s,
        persist_checks=a.persist_checks,
        min_confidence=a.min_confidence,
        sure_confidence=a.sure_confidence,
        candidates=cands,
        hysteresis_file=a.hysteresis_file or '',
        thermal_file=a.thermal_file or '',
        params_file=a.params_file or '',
    )


def _line(v: Verdict) -> str:
    what = f'{v.cause} ({v.subsystem})' if v.level != 'OK' else 'the wrist is its model'
    p = ', '.join(f'{k} = {x:.3g}' for k, x in v.parameters.items())
    since = f', since {v.since_s:.1f} s' if v.since_s is not None and v.level != 'OK' else ''
    return f'{v.t_s:8.1f} s  {v.level:5s} {what}{": " + p if p else ""}{since}  [confidence {v.confidence:.2f}]'


def run_cli(a: argparse.Namespace) -> int:
    """``sma-wrist monitor BAG``: exit 0 ok, 2 bad input, 1 internal error."""
    try:
        if a.out:
            from sma_wrist.monitor import history_format

            history_format(a.out)
            from sma_wrist.outputs import check_output_file

            check_output_file(
                a.out,
                '--out',
                [a.bag] + [f for f in (a.hysteresis_file, a.thermal_file, a.params_file) if f],
                MonitorInputError,
            )
        cfg = config_from_args(a)
        recording = Recording.from_options(getattr(a, 'topic', None), getattr(a, 'joint', None))
        last = [None]

        def show(v: Verdict) -> None:  # the timeline: a line when the published verdict changes
            key = (v.level, v.cause)
            if not a.json and key != last[0]:
                print(_line(v), flush=True)
            last[0] = key

        res = monitor_bag(a.bag, cfg, recording, show)
    except (MonitorInputError, DiagnoseInputError, ContractError, SmaWristError) as exc:
        print(json.dumps({'error': str(exc)}) if a.json else f'error: {exc}', file=sys.stdout if a.json else sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - the command never shows a traceback
        msg = f'internal error {type(exc).__name__}: {exc} (please report with the bag)'
        print(json.dumps({'error': msg}) if a.json else f'error: {msg}', file=sys.stdout if a.json else sys.stderr)
        return 1
    mon = res.pop('_monitor')
    if a.out:
        write_history(a.out, mon.history, res['episodes'])
    if a.json:
        print(json.dumps(res))
        return 0
    for w in res['warnings']:
        print(f'warning: {w}')
    if not res['verdicts']:
        print(
            f'no check: the bag holds {res["duration_s"]:.1f} s, a check needs {cfg.window_s + cfg.settle_s:g} s '
            f'(--window-s + --settle-s)'
        )
    for e in res['episodes']:
        until = f'until {e["until_s"]:.1f} s' if e['until_s'] is not None else 'to the end'
        print(
            f'{e["level"]} {", ".join(e["causes"]) or "-"} ({e["subsystem"] or "-"}): seen from {e["onset_s"]:.1f} s, '
            f'raised at {e["raised_s"]:.1f} s, {until}'
        )
    print(
        f'{res["checks"]} checks over {res["duration_s"]:.1f} s of bag in {res["wall_s"]:.1f} s '
        f'(mean {res["check_cpu_s"]:.2f} s CPU per check); model: {res["model"]}'
    )
    if a.out:
        print(f'verdict history: {a.out}')
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    from sma_wrist.cli_options import monitor_arguments

    ap = monitor_arguments(
        argparse.ArgumentParser(
            prog='sma-wrist monitor', description='The live model monitor on a recorded bag (doc/howto/monitor.md).'
        )
    )
    return run_cli(ap.parse_args(list(argv) if argv is not None else None))


if __name__ == '__main__':
    sys.exit(main())
