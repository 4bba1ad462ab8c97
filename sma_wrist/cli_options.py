"""Options of the sub-commands whose implementations are slow to import.

``sma-wrist`` builds its whole parser for every command; defining these options next to their
implementations made every command import scipy.signal and the plant (~1.5 s) before it did
anything. The implementations import them from here for their own ``python -m`` entry points.
"""

from __future__ import annotations

import argparse


def nonnegative_int(text: str) -> int:
    """An integer >= 0: seeds (numpy's SeedSequence raises on a negative one, deep in a run) and counts."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not an integer') from None
    if v < 0:
        raise argparse.ArgumentTypeError(f'{text!r} must be >= 0')
    return v


def diagnose_arguments(ap: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``diagnose`` options (shared by ``sma-wrist diagnose`` and ``python -m sma_wrist.diagnose``)."""
    ap.add_argument('bag', help='rosbag2 directory (or .mcap) recorded per msg_defs/topics.yaml')
    ap.add_argument('--json', action='store_true', help='print one JSON object instead of text')
    ap.add_argument('--report', metavar='DIR', help='write diagnosis.md, PNG plots and extended_params.yaml here')
    ap.add_argument('--params', metavar='FILE', help='write the extended model as a plant_sim params file')
    ap.add_argument('--candidates', metavar='IDS', help='comma-separated catalogue ids to try (default: all)')
    ap.add_argument(
        '--hysteresis-file',
        metavar='FILE',
        help='the wire model to replay: hysteresis.yaml from sma-wrist identify (default: built-in set)',
    )
    ap.add_argument(
        '--thermal-file',
        metavar='FILE',
        help="the TEMs' heat balance to replay: thermal.yaml from sma-wrist identify thermal (default: Table 4.9)",
    )
    ap.add_argument(
        '--params-file',
        metavar='FILE',
        help="the model to replay: that of a params file's plant_sim (else hardware_bridge) section, e.g. "
        "sma-wrist commission's wrist_params.yaml: its model files, pre-load and model.* values "
        '(--hysteresis-file / --thermal-file replace its files)',
    )
    recording_arguments(ap)
    return ap


def monitor_arguments(ap: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``monitor`` options (``sma-wrist monitor`` and ``python -m sma_wrist.monitor.playback``); the defaults
    are twin_monitor's parameters (sma_wrist.monitor.MonitorConfig)."""
    ap.add_argument(
        'bag', help='rosbag2 directory (or .mcap) recorded per msg_defs/topics.yaml, played through as if live'
    )
    ap.add_argument(
        '--json',
        action='store_true',
        help='print one JSON object (verdicts, episodes, onset_s, wall_s) instead of the timeline',
    )
    ap.add_argument('--out', metavar='FILE', help='write the verdict history here (.csv, .json or .md)')
    ap.add_argument(
        '--window-s',
        type=float,
        default=45.0,
        metavar='S',
        help='scored part of the rolling window the diagnosis checks [s] (default 45)',
    )
    ap.add_argument(
        '--settle-s',
        type=float,
        default=20.0,
        metavar='S',
        help="lead-in before it that only settles the replays' memory [s] (default 20)",
    )
    ap.add_argument(
        '--check-period-s', type=float, default=15.0, metavar='S', help='bag time between two checks [s] (default 15)'
    )
    ap.add_argument(
        '--persist-checks',
        type=int,
        default=2,
        metavar='N',
        help='consecutive checks that must agree before a verdict is raised or cleared (default 2)',
    )
    ap.add_argument(
        '--min-confidence',
        type=float,
        default=0.5,
        metavar='P',
        help='a discrepancy found with this confidence (0-1) or lower counts as OK (default 0.5)',
    )
    ap.add_argument(
        '--sure-confidence',
        type=float,
        default=0.95,
        metavar='P',
        help='a cause named with at least this confidence is raised by one check (default 0.95)',
    )
    ap.add_argument('--candidates', metavar='IDS', help='comma-separated catalogue ids to try (default: all)')
    ap.add_argument(
        '--hysteresis-file',
        metavar='FILE',
        help='the wire model: hysteresis.yaml from sma-wrist identify (default: built-in set)',
    )
    ap.add_argument(
        '--thermal-file',
        metavar='FILE',
        help="the TEMs' heat balance: thermal.yaml from sma-wrist identify thermal (default: Table 4.9)",
    )
    ap.add_argument(
        '--params-file',
        metavar='FILE',
        help="a params file's plant model (plant_sim's section, else hardware_bridge's: a commissioned "
        "wrist_params.yaml, or a diagnosis' extended_params.yaml): the twin runs it, the checks replay it, and the "
        'monitor stays OK while the wrist keeps to it',
    )
    recording_arguments(ap)
    return ap


def recording_arguments(ap: argparse.ArgumentParser) -> None:
    """``--topic`` / ``--joint``: read a bag recorded on another rig as if it followed msg_defs/topics.yaml."""
    ap.add_argument(
        '--topic',
        action='append',
        metavar='CONTRACT=RECORDED',
        help='the bag has the contract topic CONTRACT under the name RECORDED, e.g. '
        '/wrist/joint_states=/joint_states; repeatable',
    )
    ap.add_argument(
        '--joint',
        metavar='NAME',
        help="the wrist's joint in the bag's sensor_msgs/JointState messages "
        "(default: the contract's; needed when they carry several joints)",
    )


def emulator_arguments(ap: argparse.ArgumentParser) -> None:
    """Options of ``sma-wrist emulate-device`` (also ``python -m sma_wrist.hw.emulator``)."""
    ap.add_argument('--port', default=None, help='create a symlink to the pty here (default: print the pty path)')
    ap.add_argument('--rate-hz', type=float, default=1000.0, help='sample rate in device time [Hz] (default 1000)')
    ap.add_argument('--time-scale', type=float, default=1.0, help='device seconds per wall second (default 1)')
    ap.add_argument('--payload-kg', type=float, default=0.3, help='payload at 0.09 m [kg] (default 0.3)')
    ap.add_argument('--noise-counts', type=float, default=2.0, help='ADC noise, std dev [counts] (default 2)')
    ap.add_argument('--latency-ms', type=float, default=1.0, help='command -> drive delay, device time [ms]')
    ap.add_argument('--watchdog-s', type=float, default=0.5, help='zero drive without commands [device s]')
    ap.add_argument(
        '--no-drive-readback',
        action='store_true',
        help="a firmware without the drive read-back: the host's D frame is ignored, samples carry no applied drive",
    )
    ap.add_argument(
        '--seed', type=nonnegative_int, default=0, help='seed of the ADC noise and injected garbage (default 0)'
    )
    ap.add_argument(
        '--thermocouple-offsets-C',
        default='0,0,0,0',
        help='sensor errors of muscle 1, muscle 2, TEM face 1, TEM face 2 [degC]',
    )
    ap.add_argument(
        '--thermocouple-rate-hz',
        type=float,
        default=0.0,
        metavar='HZ',
        help='the muscle thermocouples read by a converter chip at this rate, each sample repeating its '
        'last reading (a MAX31855: ~10 Hz; default 0: through the ADC at every sample)',
    )
    ap.add_argument(
        '--thermocouple-resolution-C',
        type=float,
        default=0.0,
        metavar='DEGC',
        help="that chip's resolution (a MAX31855: 0.25 degC; default 0: none)",
    )
    ap.add_argument('--garbage-rate', type=float, default=0.0, help='probability of garbage before a line')
    ap.add_argument('--checksum-error-rate', type=float, default=0.0, help='probability of a wrong CRC per line')
    ap.add_argument('--partial-rate', type=float, default=0.0, help='probability of a cut line')
    ap.add_argument('--reset-every-s', type=float, default=0.0, help='device reset period [device s] (0: never)')
    ap.add_argument('--unplug-every-s', type=float, default=0.0, help='unplug period [device s] (0: never)')
    ap.add_argument('--unplug-wall-s', type=float, default=0.5, help='how long an unplug lasts [wall s]')
    ap.add_argument('--duration', type=float, default=None, help='stop after this many wall seconds')
    # checked in config_from_args: the registry's import would load the plant into every command's start-up
    ap.add_argument(
        '--plant',
        default='model',
        help="the wrist behind the device: 'model' the controllers' own (default), or a registered plant "
        'that is not (phase_fraction: another wire model; sdgpi: the model perturbed)',
    )
    ap.add_argument(
        '--scenario-file',
        default=None,
        metavar='JSON',
        help="that plant's perturbations {name: value} (a row of sma-wrist sweep's results.jsonl will do)",
    )
    ap.add_argument(
        '--params-file',
        action='append',
        default=[],
        metavar='FILE',
        help='the wire, TEMs and pre-load plant_sim would simulate with this ROS params file '
        "(applied after config/wrist.yaml; repeatable), e.g. an identified wire's wrist_params.yaml",
    )
    ap.add_argument(
        '--transition-shift-C',
        type=float,
        default=None,
        metavar='DEGC',
        help="a wire transforming this much hotter (> 0) or colder than the model's (the model so "
        'perturbed, --plant sdgpi, unless --plant names another; within +-15 degC)',
    )
    ap.add_argument(
        '--tem-gain-scale',
        type=float,
        default=None,
        metavar='K',
        help="TEMs K times as strong as the model's (0.5-1.5; < 1: weaker), as --transition-shift-C",
    )
    # one TEM weaker than the other (a poor thermal contact, a supply lead's drop): --tem-gain-scale scales both
    ap.add_argument(
        '--tem-drive-scale',
        default=None,
        metavar='S1,S2',
        help="TEM 1 and TEM 2 get these fractions of their driver's voltage (each in (0, 2]; e.g. 0.8,1: "
        'TEM 1 20 %% weaker); default 1,1',
    )
    # wiring faults of a wrist as built: what `sma-wrist commission` finds (doc/howto/commission.md)
    ap.add_argument(
        '--swap-tem-polarity',
        type=int,
        action='append',
        metavar='N',
        help="TEM N's (1 or 2) leads swapped: its drive cools where it should heat; repeatable",
    )
    ap.add_argument(
        '--swap-tem-channels',
        action='store_true',
        help='driver output 1 wired to TEM 2 (on muscle 2) and output 2 to TEM 1',
    )
    ap.add_argument(
        '--swap-thermocouples',
        action='store_true',
        help="the muscle thermocouples swapped: ADC channel 1 reads muscle 2's, channel 2 muscle 1's",
    )
    ap.add_argument(
        '--reverse-angle', action='store_true', help="the potentiometer's outer leads swapped: it reads 65535 - counts"
    )
    ap.add_argument(
        '--broken-wire',
        type=int,
        default=None,
        metavar='N',
        help="muscle N's (1 or 2) wire does not pull (broken, unhooked): heating it moves nothing",
    )
    # effects that begin mid-run: what the twin monitor must notice (doc/howto/monitor.md)
    ap.add_argument(
        '--effect',
        action='append',
        default=[],
        metavar='KIND:CHANNEL:VALUE@ONSET_S[+RAMP_S]',
        help='from ONSET_S [device s] after the first command on: offset/gain/lag/drift of thermocouple T1 or T2 or the potentiometer q '
        '(degC or rad / fraction / s / per h), or on channel plant: tem_weak (fraction both TEMs lose), payload '
        '(kg added), ambient_drift (degC/h), transition_drift (degC the wires transform hotter, reached over '
        'RAMP_S); e.g. offset:T1:3@60, transition_drift:plant:6@60+120; repeatable; --plant model only for plant',
    )


def commission_arguments(ap: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Options of ``sma-wrist commission`` (doc/howto/commission.md)."""
    ap.add_argument('--hardware', metavar='PORT', default=None, help='the wrist controller on this serial port')
    ap.add_argument(
        '--sim',
        action='store_true',
        help='the simulated plant (of --params-file) behind an emulated device instead of a port',
    )
    ap.add_argument('--out', required=True, metavar='DIR', help='report (commission.md, PNGs) and wrist_params.yaml')
    ap.add_argument(
        '--payload-kg',
        type=float,
        default=None,
        metavar='M',
        help='payload as mounted [kg] (written into the params file)',
    )
    ap.add_argument(
        '--params-file',
        action='append',
        default=[],
        metavar='FILE',
        help="ROS params file(s) after config/wrist.yaml: the bridge's calibration to start from (and "
        'the plant of --sim); carried into the params file written',
    )
    ap.add_argument(
        '--accept-fixes',
        action='store_true',
        help='write the wiring faults a bridge parameter corrects '
        'into the params file and go on (after verifying them)',
    )
    ap.add_argument(
        '--bring-up-only',
        action='store_true',
        help='stop after the bring-up (wiring checked, bridge calibration written): no excitation or identification',
    )
    ap.add_argument(
        '--heat-V',
        type=float,
        default=20.0,
        metavar='V',
        help='drive of the angle check (default 20; the wiring pulses are 6 V)',
    )
    ap.add_argument(
        '--max-muscle-C',
        type=float,
        default=75.0,
        metavar='DEGC',
        help='bring-up temperature limit of the muscles (default 75)',
    )
    ap.add_argument(
        '--controllers',
        default=None,
        metavar='NAMES',
        help="controllers the verification runs (comma separated, or all; default: the params files' "
        'adaptive_controller mode, inverse_adaptive in config/wrist.yaml)',
    )
    ap.add_argument(
        '--verify-s',
        type=float,
        default=157.7,
        metavar='S',
        help='device seconds of each verification run, defaults and commissioned per controller (default 157.7: '
        "run's 30 s soft start and two full cycles of the sine, compared with their spread; 0: no verification)",
    )
    ap.add_argument('--baud-rate', type=int, default=921600, help='serial baud rate (default 921600)')
    ap.add_argument(
        '--stall-s',
        type=float,
        default=1.0,
        metavar='S',
        help='no valid frame from the device for this long (wall) stops the procedure (default 1)',
    )
    ap.add_argument('--seed', type=nonnegative_int, default=0, help="--sim: the emulated sensors' noise seed")
    ap.add_argument('--json', action='store_true', help='print one JSON object')
    return ap


def sweep_arguments(p: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Options of ``sma-wrist sweep`` (doc/howto/sweep.md)."""
    p.add_argument('--plants', type=int, default=20, help='number of sampled plants N (default 20)')
    p.add_argument(
        '--seed', type=nonnegative_int, default=0, help='seed of the plant sample and the sensor noise (default 0)'
    )
    p.add_argument('--controllers', default='inverse_adaptive,direct_adaptive,pid', help='comma separated')
    p.add_argument(
        '--payloads',
        default=None,
        help="kg, comma separated: every plant at each (default: each plant's sampled 0.1-0.6 kg)",
    )
    p.add_argument('--duration', type=float, default=126.0, help='simulated seconds per loop (default 126)')
    p.add_argument('--plant', default='sdgpi', help='registered plant (sma_wrist.plants.PLANTS; default sdgpi)')
    p.add_argument(
        '--perturb',
        action='append',
        default=[],
        metavar='NAME=LO:HI',
        help='replace a perturbation range of the family (NAME=VALUE fixes it); repeatable',
    )
    p.add_argument('--only', action='store_true', help='sample only the --perturb axes (others nominal)')
    p.add_argument('--no-nominal', action='store_true', help='skip the nominal-plant loops run side by side')
    p.add_argument(
        '--chunk', type=int, default=192, help='most loops per vectorised simulation / Dask task (default 192)'
    )
    p.add_argument('--heatmap-axes', default='transition_shift_C,stroke_scale', help='two perturbation names')
    p.add_argument(
        '--scheduler',
        default=None,
        metavar='ADDRESS',
        help='run the chunks on this Dask distributed scheduler (pip install "sma_wrist[dask]")',
    )
    p.add_argument(
        '--workers',
        type=int,
        default=1,
        metavar='N',
        help='run the chunks in N local processes (0: one per available core; default 1)',
    )
    p.add_argument('--out', default='runs/sweep', help='output directory (results.jsonl, sweep.json, table, PNGs)')
    p.add_argument(
        '--reach',
        action='store_true',
        help="also each plant's reach floor (the least max error any controller can have on it; "
        '~2-5 s per plant) and the figures over the plants where it is under 15 %%',
    )
    p.add_argument(
        '--params-file',
        action='append',
        default=[],
        metavar='FILE',
        help='ROS params file of the node graph applied after config/wrist.yaml (as sma-wrist run '
        '--params-file; e.g. your identified hysteresis_file / thermal_file); repeatable. '
        'A parameter the sweep cannot honour is refused (doc/howto/sweep.md)',
    )
    p.add_argument('--json', action='store_true', help='print the summary as JSON')
    p.add_argument('--quiet', action='store_true', help='no progress bar')
    return p
