"""``sma-wrist``: run the closed loop, inspect bags, benchmark (and the later tools).

Every subcommand reports bad input as ``error: ...`` with exit code 2, never a traceback.
The embedded rclpy runtime is activated before any node module is imported; where ROS 2
is sourced it steps aside (``sma-wrist run`` then tells you to use ``ros2 launch``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from typing import Any

from sma_wrist.cli_options import (
    commission_arguments,
    diagnose_arguments,
    emulator_arguments,
    monitor_arguments,
    nonnegative_int,
    recording_arguments,
    sweep_arguments,
)
from sma_wrist.contract import PAYLOAD_RANGE_KG
from sma_wrist.core.errors import SmaWristError
from sma_wrist.outputs import BENCH_OUT_HELP


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f'{text!r} must be a finite number > 0')
    return v


def _soft_start(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not (math.isfinite(v) and 0.0 <= v <= 120.0):
        raise argparse.ArgumentTypeError(f'{text!r} must be a number of seconds in [0, 120]')
    return v


def _payload(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    lo, hi = PAYLOAD_RANGE_KG
    if not (math.isfinite(v) and lo <= v <= hi):
        raise argparse.ArgumentTypeError(f'payload {text!r} kg is outside [{lo:g}, {hi:g}] kg')
    return v


def _live_address(text: str) -> tuple[str, int]:
    from sma_wrist.runtime.live import parse_address

    try:
        return parse_address(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _real_time_factor(text: str) -> float:
    """A positive multiple of real time, or 'max' (inf: as fast as the machine allows)."""
    return math.inf if text.strip().lower() == 'max' else _positive_float(text)


def _start_live(a: argparse.Namespace) -> tuple[Any, float | None]:
    """The live server of ``run --foxglove`` (its address checked, so a port in use stops the run before anything is
    written; it listens once the graph is built) and the run's real-time factor: 1 with --foxglove, as fast as
    possible without, --real-time-factor's where given; a hardware run is paced by its device."""
    given = a.real_time_factor is not None
    if a.hardware and given:
        raise SmaWristError(
            '--real-time-factor applies to simulated runs: the device paces a hardware run (an emulated one with '
            'emulate-device --time-scale)'
        )
    factor = a.real_time_factor if given else (1.0 if a.foxglove and not a.hardware else None)
    factor = None if factor == math.inf else factor
    if a.foxglove is None:
        return None, factor
    from sma_wrist.runtime.live import LiveServer

    host, port = a.foxglove
    pace = 'paced by the device' if a.hardware else (f'{factor:g}x real time' if factor else 'unpaced')

    def announce(server: LiveServer) -> None:  # once the graph is built and the server listens
        print(
            f'live view: {server.url} ({pace}); in Foxglove: Open connection > Foxglove WebSocket > {server.url}, '
            'layout config/foxglove/wrist.json (doc/howto/live_view.md)',
            file=sys.stderr,
            flush=True,
        )

    server = LiveServer(host, port, announce=announce)
    return server, factor


def _activate() -> None:
    from sma_wrist import runtime

    if not runtime.activate():
        raise SmaWristError(
            'ROS 2 is sourced in this shell, so the embedded runtime is off: use '
            '`ros2 launch sma_wrist wrist_sim.launch.py` there, or run sma-wrist from a shell '
            'without ROS 2'
        )


def _print_metrics(summary: Any) -> None:
    m = summary.metrics
    print(
        f'run: {summary.controller}, payload {summary.payload_kg:g} kg, {summary.sim_time_s:.1f} s simulated '
        f'in {summary.wall_s:.1f} s wall ({summary.real_time_factor:.1f}x real time)'
        + (' -- INTERRUPTED' if summary.interrupted else '')
    )
    if summary.bag:
        print(f'bag: {summary.bag} ({summary.messages_recorded} messages, rosbag2/MCAP)')
    if summary.metrics_missing:
        print(f'no tracking metrics: {summary.metrics_missing}')
    if m:
        total = m['total_abs_error_pct']
        where = 'over the last full cycle' if m.get('window') == 'last_cycle' else 'over the run'
        of = 'reference range' if m.get('range_of', 'the reference') == 'the reference' else "the Sec. 6.1 sine's range"
        print(f'max error        {m["max_error_pct"]:8.2f} % of {of} ({m["max_abs_error_rad"]:.4f} rad) {where}')
        # the reference as published: from the wrist's measured angle, joined to the shape over trajectory_generator's
        # soft_start_s; the figure includes the muscles' warm-up from ambient, when the wrist cannot move yet
        print(
            f'whole run        {m["max_error_pct_all"]:8.2f} % max, {m["rms_error_pct_all"]:.2f} % RMS (against the '
            "reference as published, from the measured angle with --soft-start; includes the muscles' warm-up)"
        )
        print(f'RMS error        {m["rms_error_pct"]:8.2f} % ({m["rms_error_rad"]:.4f} rad)')
        print(
            'total abs error  '
            + (
                f'{total:8.0f} % (Table 6.2: sum of |e| % over the last full cycle at 1 kHz)'
                if total is not None
                else '     n/a (needs one full 62.8 s cycle)'
            )
        )
        if m.get('peak_command_V') is not None:
            print(f'peak TEM command {m["peak_command_V"]:8.2f} V')


def _prepare_bag(path: str | None, overwrite: bool) -> None:
    """Refuse to clobber anything but a previous bag; --overwrite removes that one."""
    import shutil
    from pathlib import Path

    if path is None or not Path(path).exists():
        return
    p = Path(path)
    is_bag = p.is_dir() and ((p / 'metadata.yaml').exists() or any(p.glob('*.mcap')))
    if not overwrite:
        raise SmaWristError(f'{p} already exists; choose a new --bag directory or pass --overwrite')
    if not is_bag:
        raise SmaWristError(f'{p} exists and is not a rosbag2 directory; refusing to overwrite it')
    shutil.rmtree(p)


def _print_next(bag: str | None, plot: str | None) -> None:
    """Where the run's files are and what to try next."""
    if plot:
        print(f'plot: {plot} (angle and reference, error, muscle temperatures, TEM commands)')
    if bag:
        print(
            f'next: sma-wrist compare {bag} OTHER_BAG --plot cmp.png   (this run beside another)'
            if plot
            else f'next: sma-wrist compare {bag} --plot run.png   (the tracking plot; or run with --plot FILE.png)'
        )
    print(
        ('      ' if bag else 'next: ')
        + "sma-wrist run --params-file my.yaml ...   (change a gain or limit: copy a node's section of "
        "config/wrist.yaml, e.g. adaptive_controller's pid.kp; every parameter with its range: the documentation's "
        'node reference, or `ros2 param describe` under ROS 2)'
    )


def cmd_run(a: argparse.Namespace) -> int:
    if a.plot is not None:  # drawn from the recording, as the metrics are (a temporary one without --bag)
        from sma_wrist.runs import check_plot_file

        check_plot_file(a.plot, [a.bag] if a.bag else [], 'run.png')
    live, factor = _start_live(a)
    try:
        return _run(a, live, factor)
    finally:
        if live is not None:
            live.close()


def _run(a: argparse.Namespace, live: Any, real_time_factor: float | None) -> int:
    """:func:`cmd_run` once its live server (or none) is up."""
    _prepare_bag(a.bag, a.overwrite)
    _activate()
    from sma_wrist.closed_loop import NothingToMeasure, print_progress, run_closed_loop

    if a.controller is None or a.payload_kg is None:  # the params files' choice, else config/wrist.yaml's
        from sma_wrist.closed_loop import file_choices

        mode, payload = file_choices(a.params_file or (), a.hardware is not None)
        a.controller = a.controller or mode
        a.payload_kg = payload if a.payload_kg is None else a.payload_kg
    from sma_wrist.closed_loop import file_soft_start
    from sma_wrist.core.control.trajectory import RUN_SOFT_START_S

    # --soft-start, else a params file's soft_start_s, else run's own default (the node's is 0)
    soft = a.soft_start if a.soft_start is not None else file_soft_start(a.params_file or ())
    extra = {'/trajectory_generator': {'soft_start_s': RUN_SOFT_START_S if soft is None else soft}}
    if a.hardware:
        extra['/hardware_bridge'] = {'port': a.hardware}
    # without --bag the run is recorded to a temporary bag all the same: its metrics are the bag's, whether kept
    try:
        summary = run_closed_loop(
            a.controller,
            a.payload_kg,
            a.duration,
            a.bag,
            a.params_file or (),
            progress=None if a.quiet else print_progress,
            hardware=a.hardware is not None,
            extra_params=extra,
            measure=True,
            monitor=None if a.monitor is None else {'history_file': a.monitor},
            live=live,
            real_time_factor=real_time_factor,
        )
    except NothingToMeasure as exc:  # printed as a run without metrics, exit 2
        summary = exc.summary
    if a.json:
        print(
            json.dumps(
                {
                    'bag': summary.bag,
                    'controller': summary.controller,
                    'payload_kg': summary.payload_kg,
                    'sim_time_s': summary.sim_time_s,
                    'wall_s': summary.wall_s,
                    'real_time_factor': summary.real_time_factor,
                    'messages': summary.messages_recorded,
                    'interrupted': summary.interrupted,
                    'metrics': summary.metrics,
                    'metrics_missing': summary.metrics_missing or None,
                    **({'monitor': summary.monitor} if summary.monitor is not None else {}),
                },
                indent=2,
            )
        )
    if a.plot is not None and summary.run is not None:
        from sma_wrist.runs import plot_runs

        plot_runs([summary.run], [f'{summary.controller} {summary.payload_kg:g} kg'], a.plot, str(a.bag or ''))
    if not a.json:
        _print_metrics(summary)
        if summary.monitor is not None:
            m = summary.monitor
            v = m['verdict']
            print(
                f'twin_monitor: {m["checks"]} checks ({m["skipped_checks"]} skipped while one ran, '
                f'{m["behind_s"]:.1f} s behind the wrist at the end); last verdict: '
                + (f'{v["level"]} {v["cause"] or ""} {v["subsystem"] or ""}'.strip() if v else 'none yet')
                + (f'; history: {a.monitor}' if a.monitor else '')
            )
        _print_next(summary.bag, a.plot)
    if summary.interrupted:
        return 130
    return 2 if summary.metrics_missing else 0  # a run that ended with nothing to measure failed to measure


def cmd_info(a: argparse.Namespace) -> int:
    from sma_wrist.bag import bag_info

    info = bag_info(a.bag)
    if info.damage:  # the counts below are what the bag should hold, not what can be read
        print(f'warning: {info.path}: the bag is damaged: {info.damage}', file=sys.stderr)
    if a.json:
        print(
            json.dumps(
                {
                    'path': str(info.path),
                    'storage': info.storage,
                    'duration_s': info.duration,
                    'messages': info.message_count,
                    'damaged': info.damage or None,
                    'topics': {k: {'type': v.type, 'count': v.count} for k, v in info.topics.items()},
                },
                indent=2,
            )
        )
        return 1 if info.damage else 0
    kind = f'rosbag2 metadata v{info.version}' if info.version else 'a bare file, no rosbag2 metadata'
    print(f'bag:      {info.path} ({kind}, {info.storage})')
    print(f'duration: {info.duration:.3f} s    messages: {info.message_count}')
    if info.damage:
        print(f'DAMAGED:  {info.damage}')
    width = max((len(k) for k in info.topics), default=5)
    for name, t in sorted(info.topics.items()):
        print(f'  {name:<{width}}  {t.count:8d}  {t.type}')
    return 1 if info.damage else 0


def cmd_bench(a: argparse.Namespace) -> int:
    from sma_wrist import bench

    result = bench.run(a.section or None, quick=a.quick, out=a.out)
    print(json.dumps(result, indent=2) if a.json else bench.format_text(result))
    return 0


def cmd_emulate_device(a: argparse.Namespace) -> int:
    from sma_wrist.hw.emulator import run_from_args

    return run_from_args(a)


def _csv(kind: Callable[[str], Any]) -> Callable[[str], list[Any]]:
    def parse(text: str) -> list[Any]:
        items = [x.strip() for x in text.split(',') if x.strip()]
        if not items:
            raise argparse.ArgumentTypeError('empty list')
        return [kind(x) for x in items]

    return parse


def _controller(text: str) -> str:
    from sma_wrist.closed_loop import CONTROLLERS

    if text not in CONTROLLERS:
        raise argparse.ArgumentTypeError(f'{text!r} is not one of {", ".join(CONTROLLERS)}')
    return text


def cmd_experiment(a: argparse.Namespace) -> int:
    from sma_wrist.experiment import run_experiment

    table = run_experiment(
        a.controllers,
        a.payloads,
        a.out,
        duration_s=a.duration,
        workers=a.workers,
        params_files=a.params_file or (),
        plots=not a.no_plots,
        family=a.family,
        family_seed=a.family_seed,
    )
    print(
        json.dumps(table, indent=2)
        if a.json
        else f'{len(table["runs"])} runs in {table["wall_s"]:.0f} s wall; report: {a.out}/report.md'
    )
    return 0


def cmd_compare(a: argparse.Namespace) -> int:
    from sma_wrist.contract import Recording
    from sma_wrist.runs import compare_runs

    rows = compare_runs(a.bags, a.plot, Recording.from_options(a.topic, a.joint))
    for r in rows:  # a truncated bag's metrics cover only what was recorded before the cut
        if r['damaged']:
            print(
                f'warning: {r["bag"]}: {r["damaged"]}; its metrics cover only the messages that could be read '
                f'({r["duration_s"]:.1f} s from the first to the last)',
                file=sys.stderr,
            )
        if r['dropped']:
            print(f'warning: {r["bag"]}: {r["dropped"]}', file=sys.stderr)
    if a.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f'{"bag":40s} {"max %":>7s} {"RMS %":>7s} {"total %":>9s} {"peak V":>7s} {"payload":>8s}')
    for r in rows:
        tot = f'{r["total_abs_error_pct"]:9.0f}' if r['total_abs_error_pct'] is not None else '      n/a'
        pk = f'{r["peak_command_V"]:7.2f}' if r['peak_command_V'] is not None else '    n/a'
        pay = f'{r["payload_kg"]:8.2f}' if r['payload_kg'] is not None else '     n/a'
        print(f'{r["bag"][-40:]:40s} {r["max_error_pct"]:7.2f} {r["rms_error_pct"]:7.2f} {tot} {pk} {pay}')
    return 0


def cmd_commission(a: argparse.Namespace) -> int:
    from sma_wrist.commission.run import run_cli

    return run_cli(a)


def cmd_diagnose(a: argparse.Namespace) -> int:
    from sma_wrist.diagnose import run_cli

    return run_cli(a)


def cmd_monitor(a: argparse.Namespace) -> int:
    from sma_wrist.monitor.playback import run_cli

    return run_cli(a)


def cmd_sweep(a: argparse.Namespace) -> int:
    from sma_wrist.core.errors import ParameterError
    from sma_wrist.plants.spread import FAMILY
    from sma_wrist.sweep.run import Progress, SweepConfig, format_table, make_cases, parse_perturbations, run_sweep

    ranges = parse_perturbations(a.perturb)
    try:
        payloads = tuple(float(x) for x in a.payloads.split(',')) if a.payloads else None
    except ValueError:
        raise ParameterError(f'--payloads {a.payloads!r}: comma separated numbers [kg]') from None
    axes = tuple(x.strip() for x in a.heatmap_axes.split(','))
    if len(axes) != 2:
        raise ParameterError(f'--heatmap-axes {a.heatmap_axes!r}: give two perturbation names')
    cfg = SweepConfig(
        n_plants=a.plants,
        seed=a.seed,
        controllers=tuple(x.strip() for x in a.controllers.split(',')),
        payloads=payloads,
        duration_s=a.duration,
        plant=a.plant,
        ranges=ranges if a.only else {**FAMILY, **ranges},
        chunk=a.chunk,
        nominal=not a.no_nominal,
        heatmap_axes=axes,
        reach=a.reach,
        params_files=tuple(a.params_file),
    )  # type: ignore[arg-type]
    progress = None if a.quiet else Progress(len(make_cases(cfg)))
    res = run_sweep(cfg, a.out, a.scheduler, progress, workers=a.workers)
    if a.json:
        print(json.dumps({k: v for k, v in res.to_json().items() if k != 'rows'}, indent=2))
    else:
        print(format_table(res.summary))
        print(
            f'{len(res.rows)} closed loops in {res.wall_s:.1f} s wall; '
            + ', '.join(f'{k}: {v}' for k, v in res.files.items())
        )
    if res.interrupted:
        print(f'interrupted: {len(res.rows)} finished loops kept in {a.out}', file=sys.stderr)
        return 130
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog='sma-wrist', description='SMA wrist simulation, recording and analysis tools.')
    sub = ap.add_subparsers(dest='command', required=True, metavar='COMMAND')

    r = sub.add_parser('run', help='run the closed loop on the embedded runtime, record a bag, print metrics')
    r.add_argument(
        '--controller',
        default=None,
        choices=('inverse_adaptive', 'direct_adaptive', 'pid'),
        help="default: adaptive_controller's mode in the params files (config/wrist.yaml: inverse_adaptive)",
    )
    r.add_argument(
        '--payload-kg',
        type=_payload,
        default=None,
        help="payload at 0.09 m [kg] (default: plant_sim's payload_kg in the params files, 0.3)",
    )
    r.add_argument(
        '--duration',
        type=_positive_float,
        default=126.0,
        help='simulated seconds (default 126); with --hardware, seconds of device time from the first /clock',
    )
    r.add_argument(
        '--bag',
        default=None,
        help='rosbag2 directory to create (must not exist; without it the run is '
        'recorded to a temporary bag for its metrics, removed afterwards)',
    )
    r.add_argument('--overwrite', action='store_true', help='replace an existing bag at --bag')
    r.add_argument('--params-file', action='append', help='ROS params file applied after config/wrist.yaml')
    r.add_argument(
        '--monitor',
        nargs='?',
        const='',
        default=None,
        metavar='HISTORY',
        help='also run twin_monitor (doc/howto/monitor.md); HISTORY: write its verdict history there (.csv, '
        '.json or .md)',
    )
    r.add_argument(
        '--hardware', metavar='PORT', default=None, help='use hardware_bridge on this serial port instead of plant_sim'
    )
    r.add_argument(
        '--foxglove',
        type=_live_address,
        default=None,
        metavar='[HOST:]PORT',
        help="serve the running graph's topics to the Foxglove app over its WebSocket protocol, as foxglove_bridge "
        'does under ROS 2 (HOST default 127.0.0.1, this machine only; 0.0.0.0 for others; PORT 0: any free '
        "port); needs the extra live: pip install 'sma_wrist[live]' (doc/howto/live_view.md)",
    )
    r.add_argument(
        '--real-time-factor',
        type=_real_time_factor,
        default=None,
        metavar='X',
        help='hold simulated time to X times real time, or max: as fast as the machine allows (default: 1 with '
        "--foxglove, so that the run can be watched, else max; a hardware run goes at its device's pace)",
    )
    r.add_argument(
        '--soft-start',
        type=_soft_start,
        default=None,
        metavar='S',
        help="the reference starts at the wrist's measured angle and joins the shape over S seconds "
        '(trajectory_generator soft_start_s; default 30, 0: the shape from its first value)',
    )
    r.add_argument('--json', action='store_true', help='print one JSON object')
    r.add_argument(
        '--plot',
        default=None,
        metavar='FILE.png',
        help='write the tracking plot of the recorded run here (needs --bag): angle and reference, error, '
        'muscle temperatures, TEM commands (as compare --plot)',
    )
    r.add_argument('--quiet', action='store_true', help='no progress line')
    r.set_defaults(func=cmd_run)

    e = sub.add_parser('experiment', help='the Chapter 6 comparison: controllers x payloads, bags, report')
    e.add_argument(
        '--controllers',
        type=_csv(_controller),
        default=['inverse_adaptive', 'direct_adaptive', 'pid'],
        help='comma separated (default: all three)',
    )
    e.add_argument(
        '--payloads', type=_csv(_payload), default=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6], help='kg, comma separated'
    )
    e.add_argument('--out', default='runs/ch6', help='output directory: one bag per run, report.md, table, PNGs')
    e.add_argument('--duration', type=_positive_float, default=4 * math.pi / 0.1, help='s (default two periods)')
    e.add_argument(
        '--workers', type=nonnegative_int, default=None, help='parallel processes (default and 0: CPU count)'
    )
    e.add_argument(
        '--params-file', action='append', help='params file for every run (e.g. config/paper_table_6_1.yaml)'
    )
    e.add_argument('--no-plots', action='store_true', help='write no PNG plots')
    e.add_argument('--json', action='store_true', help='print the result table as JSON')
    e.add_argument(
        '--family',
        type=nonnegative_int,
        default=8,
        help='also run every controller x payload on this many sampled off-model plants (the sweep '
        'engine) and report them beside the nominal figures (0: none; default 8)',
    )
    e.add_argument('--family-seed', type=nonnegative_int, default=1, help='seed of the sampled plants (default 1)')
    e.set_defaults(func=cmd_experiment)

    c = sub.add_parser('compare', help='tracking metrics of recorded runs (sim or hardware), aligned on time')
    c.add_argument('bags', nargs='+', help='rosbag2 directories or files (MCAP or SQLite)')
    c.add_argument('--json', action='store_true', help='print the rows as JSON')
    c.add_argument('--plot', default=None, help='write an overlay PNG here')
    recording_arguments(c)
    c.set_defaults(func=cmd_compare)

    i = sub.add_parser('info', help='summarise a bag: topics, counts, duration')
    i.add_argument('bag', help='rosbag2 directory or one .mcap / .db3 file')
    i.add_argument('--json', action='store_true', help='print one JSON object')
    i.set_defaults(func=cmd_info)

    d = diagnose_arguments(
        sub.add_parser(
            'diagnose',
            help='what the model gets wrong in a recorded run: locate, name, extend, measure (doc/explanation/diagnosis.md)',
        )
    )
    d.set_defaults(func=cmd_diagnose)

    m = commission_arguments(
        sub.add_parser(
            'commission',
            help='bring a new wrist up: link, sensors, TEM wiring, angle direction; report and params '
            'file (doc/howto/commission.md)',
        )
    )
    m.set_defaults(func=cmd_commission)

    d = monitor_arguments(
        sub.add_parser(
            'monitor', help='the live model monitor on a recorded bag: which cause from when (doc/howto/monitor.md)'
        )
    )
    d.set_defaults(func=cmd_monitor)

    d = sub.add_parser(
        'emulate-device', help='emulated wrist controller on a pseudo-terminal (doc/explanation/protocol.md)'
    )
    emulator_arguments(d)
    d.set_defaults(func=cmd_emulate_device)

    from sma_wrist.identify import add_parser as add_identify_parser

    add_identify_parser(sub)  # identify hysteresis / thermal: each sub-command registers its own options

    w = sweep_arguments(
        sub.add_parser(
            'sweep',
            help='closed loops over sampled plants x controllers x payloads '
            '(vectorised; --scheduler: Dask), doc/howto/sweep.md',
        )
    )
    w.set_defaults(func=cmd_sweep)

    b = sub.add_parser('bench', help='benchmarks (plant, graph, ...) as numbers')
    b.add_argument('--json', action='store_true', help='print JSON instead of section.key = value lines')
    b.add_argument('--quick', action='store_true', help='short runs (smoke test of the benchmark itself)')
    b.add_argument('--section', action='append', help='only these sections')
    b.add_argument('--out', metavar='DIR', help=BENCH_OUT_HELP)
    b.set_defaults(func=cmd_bench)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    a = ap.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = a.func
    try:
        return func(a)
    except SmaWristError as e:
        print(f'error: {e}', file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader went away (`sma-wrist info BAG | head`): stop quietly as Unix tools do; stdout is pointed at
        # devnull so the interpreter's final flush does not raise again
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what the shell reports for a tool killed by it
    except FileExistsError as e:
        # a run's bag directory, or an output folder (identify/experiment --out) that is a file: only
        # run has a --bag to choose again
        hint = '; choose a new --bag directory' if getattr(a, 'command', None) == 'run' else ''
        print(f'error: {e.filename or e} already exists{hint}', file=sys.stderr)
        return 2
    except OSError as e:
        if e.filename is None:  # not a path the user named: a defect, keep its traceback
            raise
        # an output folder that cannot be made, a file that cannot be written: the user's path, said plainly
        print(f'error: cannot use {e.filename}: {e.strerror or e}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    raise SystemExit(main())
