"""A recorded run (sim or hardware bag) as aligned arrays, and its tracking metrics.

Used by ``sma-wrist run`` (metrics of the bag it just wrote), ``compare`` and the
experiment report, so every number comes from the bag, whatever produced it.
Alignment: the reference is interpolated at the joint-state stamps (both stamped on the
node clocks, i.e. simulated time under use_sim_time); samples before the first reference
are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sma_wrist.bag import BagData, BagError, read_bag
from sma_wrist.contract import IMPOSSIBLE, Recording, joint_positions
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.metrics import SEED_PERIOD_S, SEED_REFERENCE_RANGE_RAD, TrackingMetrics, tracking_metrics

FloatArray = NDArray[np.float64]

TOPICS = (
    '/wrist/joint_states',
    '/wrist/reference',
    '/wrist/muscle_1/temperature',
    '/wrist/muscle_2/temperature',
    '/wrist/tem_1/command',
    '/wrist/tem_2/command',
    '/wrist/payload',
)


@dataclass
class RunData:
    path: str
    t: FloatArray  # s, joint-state stamps
    q: FloatArray  # rad
    q_d: FloatArray  # rad, reference at t
    temperature_C: FloatArray  # (K, 2) at t (nearest previous sample)
    command_t: FloatArray  # s, receive times of TEM commands
    command_V: FloatArray  # (K_c, 2)
    payload_kg: float | None
    damage: str = ''  # what read_bag found wrong with a truncated / corrupt bag read up to its cut ('' intact)
    dropped: str = ''  # measured samples left out as no measurement (sma_wrist.contract.IMPOSSIBLE), or ''


def _stamp(msg: Any) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _series(data: BagData, topic: str) -> list[tuple[int, Any]]:
    if topic not in data:
        return []
    t_ns, msgs = data[topic]
    return list(zip(t_ns.tolist(), msgs))


def load_run(path: str | Path, recording: Recording | None = None) -> RunData:
    """Read a run bag; BagError names what is missing. A truncated bag is read up to its cut and
    ``damage`` says so: its metrics cover only part of the run, which compare must not hide. ``recording``: how a
    bag of another rig names the contract's topics and the joint."""
    rec = recording or Recording()
    try:
        data, damage = read_bag(path, rec.recorded(TOPICS)), ''
    except BagError as exc:
        if not exc.salvaged:  # nothing of the run could be read: the bag's own problem is the reason
            raise
        data, damage = exc.salvaged, exc.problem
    data = rec.as_contract(data)
    js = _series(data, '/wrist/joint_states')
    ref = _series(data, '/wrist/reference')
    if not js or not ref:
        missing = [
            t + (f' (as {rec.topics[t]})' if t in rec.topics else '')
            for t, s in (('/wrist/joint_states', js), ('/wrist/reference', ref))
            if not s
        ]
        raise BagError(
            path,
            f'no messages on {", ".join(missing)}: a run bag needs the measured joint state '
            'and the reference (see msg_defs/topics.yaml; --topic CONTRACT=RECORDED reads a bag '
            'that names them otherwise)',
        )
    t = np.array([_stamp(m) for _, m in js])
    q = np.array(joint_positions((m for _, m in js), rec.joint))
    wild = np.abs(q) > IMPOSSIBLE['joint']  # a glitch read as an angle was a 1e8 % error
    dropped = (
        f'{int(wild.sum())} of {q.size} joint states with angles beyond +-{IMPOSSIBLE["joint"]:g} (up to '
        f'{np.abs(q[wild]).max():.3g}) are no measurement and were left out'
        if wild.any()
        else ''
    )
    q[wild] = np.nan
    tr = np.array([_stamp(m) for _, m in ref])
    qr = np.array(joint_positions((m for _, m in ref), rec.joint))
    good = np.isfinite(qr)
    if not good.any():
        raise BagError(path, '/wrist/reference holds no finite position: no error to measure')
    tr, qr = tr[good], qr[good]
    for topic, stamps in (('/wrist/joint_states', t), ('/wrist/reference', tr)):
        if stamps.size > 2 and np.unique(stamps).size < 0.5 * stamps.size:  # one pair would be all the metrics
            raise BagError(
                path,
                f'the header stamps of {topic} do not advance ({np.unique(stamps).size} distinct '
                f'in {stamps.size} messages): its publisher does not stamp them, and the error '
                'is measured by stamp',
            )
    keep = (t >= tr[0]) & (t <= tr[-1]) & np.isfinite(q)
    if not keep.any():
        finite = np.isfinite(q)
        why = (
            'no joint state has a finite position'
            if not finite.any()
            else f'the joint states are stamped {t[finite].min():.6g}..{t[finite].max():.6g} s and the reference '
            f'{tr[0]:.6g}..{tr[-1]:.6g} s: different clocks (sim time and wall time?)'
        )
        raise BagError(path, f"no measured angle inside the reference's time span: {why}")
    t, q = t[keep], q[keep]
    order = np.argsort(t, kind='stable')
    t, q = t[order], q[order]
    uniq = np.concatenate([[True], np.diff(t) > 0])
    t, q = t[uniq], q[uniq]
    q_d = np.interp(t, tr, qr)
    temps = np.full((t.size, 2), np.nan)
    for i in (1, 2):
        s = _series(data, f'/wrist/muscle_{i}/temperature')
        if s:
            ts = np.array([_stamp(m) for _, m in s])
            vs = np.array([m.temperature for _, m in s])
            k = np.clip(np.searchsorted(ts, t, side='right') - 1, 0, ts.size - 1)
            temps[:, i - 1] = vs[k]
    cmd = [_series(data, f'/wrist/tem_{i}/command') for i in (1, 2)]
    n = min(len(cmd[0]), len(cmd[1]))
    command_t = np.array([ns * 1e-9 for ns, _ in cmd[0][:n]])
    command_V = np.array([[cmd[0][k][1].data, cmd[1][k][1].data] for k in range(n)]).reshape(n, 2)
    pay = _series(data, '/wrist/payload')
    return RunData(
        str(path), t, q, q_d, temps, command_t, command_V, float(pay[-1][1].data) if pay else None, damage, dropped
    )


def unmeasurable(run: RunData) -> str:
    """Why ``run`` holds too little to measure ('' when it can be measured): an error over a run needs two measured
    angles at different times inside the reference's span. One sample (a run that ended at its first /clock) gave
    "max error 0.00 %" and "peak TEM command 0.00 V" as if measured: the soft-started reference begins at the
    measured angle."""
    span = float(run.t[-1] - run.t[0]) if run.t.size else 0.0
    if run.t.size < 2 or span <= 0.0:
        return (
            f"{run.t.size} measured angle{'' if run.t.size == 1 else 's'} inside the reference's time span "
            f'({span:.3f} s): too little to measure'
        )
    return ''


def run_metrics(run: RunData, period_s: float = SEED_PERIOD_S) -> dict[str, Any]:
    """Tracking metrics (sma_wrist.core.metrics) over the last full reference cycle, plus peak TEM command.

    Table 6.2 reports "a full cycle of wrist movement"; the first cycle of a run from rest
    holds the start-up (the muscles warm from ambient before the wrist can move; trajectory_generator's
    reference starts at the measured angle and joins the shape over its soft_start_s), so max and RMS are taken
    over the last full cycle when the run has one (``window`` says which), and over the whole run, against the
    reference as published, as ``*_all``. The % are of the reference's range, or of the
    Sec. 6.1 sine's 1.048 rad for a reference that does not move (``range_of`` says which).
    """
    # a constant reference (trajectory_generator shape: constant) has no range to take a % of: that of the
    # Sec. 6.1 sine, so a set-point run reads on the same scale as the seed's figures
    still = run.q_d.size > 0 and float(np.ptp(run.q_d)) <= 0.0
    whole: TrackingMetrics = tracking_metrics(
        run.t, run.q, run.q_d, reference_range_rad=SEED_REFERENCE_RANGE_RAD if still else None
    )
    span = run.t[-1] - run.t[0] if run.t.size else 0.0
    if span >= period_s:
        last = run.t >= run.t[-1] - period_s
        m = tracking_metrics(
            run.t[last], run.q[last], run.q_d[last], reference_range_rad=whole.reference_range_rad, period_s=None
        )
        out = m.to_dict()
        out['total_abs_error_pct'] = whole.total_abs_error_pct
        out['cycle_start_s'], out['cycle_period_s'] = whole.cycle_start_s, whole.cycle_period_s
        out['window'] = 'last_cycle'
    else:
        out = whole.to_dict()
        out['window'] = 'whole_run'
    out['max_error_pct_all'] = whole.max_error_pct
    out['rms_error_pct_all'] = whole.rms_error_pct
    finite = np.abs(run.command_V[np.isfinite(run.command_V)])  # a NaN command (TEM off) is no peak, and no JSON
    out['peak_command_V'] = float(finite.max()) if finite.size else None
    out['payload_kg'] = run.payload_kg
    out['duration_s'] = float(run.t[-1] - run.t[0]) if run.t.size else 0.0
    out['range_of'] = 'the Sec. 6.1 sine (the reference does not move)' if still else 'the reference'
    return out


__all__ = ['RunData', 'load_run', 'run_metrics', 'unmeasurable']


def plot_runs(runs: list[RunData], labels: list[str], path: str | Path, title: str = '') -> None:
    """Angle vs reference, error in % of the reference range, muscle temperatures and TEM commands, runs overlaid
    (``compare --plot`` and ``run --plot``).

    Runs are aligned on their own time axis starting at the first reference sample, so a
    hardware run recorded at wall-clock stamps lines up with a simulated one.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, (ax_q, ax_e, ax_T, ax_u) = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    for k, (run, label) in enumerate(zip(runs, labels)):
        t = run.t - run.t[0]
        span = float(np.ptp(run.q_d)) or 1.0
        if k == 0:
            ax_q.plot(t, run.q_d, 'k--', lw=1, label='q_d')
        (line,) = ax_q.plot(t, run.q, lw=1, label=label)
        ax_e.plot(t, 100.0 * (run.q - run.q_d) / span, lw=1, color=line.get_color(), label=label)
        for i, style in ((0, '-'), (1, ':')):  # muscle 1 solid, muscle 2 dotted, in the run's colour
            ax_T.plot(t, run.temperature_C[:, i], style, lw=1, color=line.get_color(), label=f'{label} muscle {i + 1}')
            if run.command_t.size:
                ax_u.plot(
                    run.command_t - run.t[0],
                    run.command_V[:, i],
                    style,
                    lw=0.8,
                    color=line.get_color(),
                    label=f'{label} TEM {i + 1}',
                )
    ax_q.set_ylabel('angle [rad]')
    ax_e.set_ylabel('error [% of reference range]')
    ax_T.set_ylabel('muscle temperature [degC]')
    ax_u.set_ylabel('TEM command [V]')
    ax_u.set_xlabel('time since first reference [s]')
    for ax in (ax_q, ax_e, ax_T, ax_u):
        ax.grid(True, alpha=0.3)
        ax.legend(loc='best', fontsize=8)
    if title:
        ax_q.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_formats() -> list[str]:
    """The file suffixes matplotlib's savefig writes ([] without matplotlib: plotting then says so itself)."""
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError:
        return []
    return sorted(FigureCanvasBase.get_supported_filetypes())


def check_plot_file(plot: str | Path, inputs: list[str | Path], example: str) -> None:
    """SmaWristError before any work if ``--plot`` cannot be written: a folder (savefig wrote <folder>.png), one of
    ``inputs``, or a suffix matplotlib does not write (its ValueError came as a traceback after the work)."""
    from sma_wrist.outputs import check_output_file

    check_output_file(plot, '--plot', inputs, example=example)
    suffix = Path(plot).suffix.lower().lstrip('.')
    formats = _plot_formats()
    if suffix and formats and suffix not in formats:
        raise SmaWristError(
            f'--plot {plot}: .{suffix} is not an image format matplotlib writes; use one of '
            f'{", ".join("." + f for f in formats)} (no suffix: PNG)'
        )


def compare_runs(
    paths: list[str | Path], plot: str | Path | None = None, recording: Recording | None = None
) -> list[dict[str, Any]]:
    """Metrics of each bag (same definitions for sim and hardware), optionally overlaid in one plot.

    A row's ``damaged`` is the problem of a bag read only up to its cut (None for an intact one). A bag with too
    little to measure (:func:`unmeasurable`) is a BagError naming it, not a row of zeros.
    """
    if plot is not None:
        check_plot_file(plot, paths, 'compare.png')
    runs = [load_run(p, recording) for p in paths]
    for p, r in zip(paths, runs):  # one sample "measured" 0.00 % (the reference starts at the measured angle)
        why = unmeasurable(r)
        if why:
            raise BagError(p, f'no tracking metrics: {why}')
    rows = [
        {'bag': str(p), **run_metrics(r), 'damaged': r.damage or None, 'dropped': r.dropped or None}
        for p, r in zip(paths, runs)
    ]
    if plot is not None:
        plot_runs(runs, [Path(p).name for p in paths], plot, 'compare')
    return rows
