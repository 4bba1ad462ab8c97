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
from sma_wrist.core.metrics import TrackingMetrics, tracking_metrics

FloatArray = NDArray[np.float64]

TOPICS = ('/wrist/joint_states', '/wrist/reference', '/wrist/muscle_1/temperature', '/wrist/muscle_2/temperature',
          '/wrist/tem_1/command', '/wrist/tem_2/command', '/wrist/payload')


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


def _stamp(msg: Any) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _series(data: BagData, topic: str) -> list[tuple[int, Any]]:
    if topic not in data:
        return []
    t_ns, msgs = data[topic]
    return list(zip(t_ns.tolist(), msgs))


def load_run(path: str | Path) -> RunData:
    """Read a run bag; BagError names what is missing. A truncated bag is read up to its cut."""
    data = read_bag(path, TOPICS, salvage=True)
    js = _series(data, '/wrist/joint_states')
    ref = _series(data, '/wrist/reference')
    if not js or not ref:
        missing = [t for t, s in (('/wrist/joint_states', js), ('/wrist/reference', ref)) if not s]
        raise BagError(path, f'no messages on {", ".join(missing)}: a run bag needs the measured joint state '
                             'and the reference (see msg_defs/topics.yaml)')
    t = np.array([_stamp(m) for _, m in js])
    q = np.array([m.position[0] for _, m in js])
    tr = np.array([_stamp(m) for _, m in ref])
    qr = np.array([m.position[0] for _, m in ref])
    keep = (t >= tr[0]) & (t <= tr[-1]) & np.isfinite(q)
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
    return RunData(str(path), t, q, q_d, temps, command_t, command_V, float(pay[-1][1].data) if pay else None)


def run_metrics(run: RunData) -> dict[str, Any]:
    """Tracking metrics (Table 6.2 definitions, sma_wrist.core.metrics) plus peak TEM command."""
    m: TrackingMetrics = tracking_metrics(run.t, run.q, run.q_d)
    out = m.to_dict()
    out['peak_command_V'] = float(np.abs(run.command_V).max()) if run.command_V.size else None
    out['payload_kg'] = run.payload_kg
    out['duration_s'] = float(run.t[-1] - run.t[0]) if run.t.size else 0.0
    return out


__all__ = ['RunData', 'load_run', 'run_metrics']
