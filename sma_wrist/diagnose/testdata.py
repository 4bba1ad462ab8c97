"""Synthetic "measured" runs with one known effect, written as bags per msg_defs/topics.yaml.

The truth is the extended model of :mod:`sma_wrist.diagnose.effects` run open loop at a
5x finer step than the 100 Hz samples (so the diagnosis' replay never matches it to the
last digit), with ONE catalogue effect injected at a random magnitude (or none), driven
by smooth random antagonistic TEM commands (random heating/cooling dwells of 45-105 s,
12-13.5 V heating, -12 V cooling, 3 s first-order smoothing), then measured: thermocouple
noise 0.05 degC, potentiometer noise 5e-4 rad, 16-bit ADC quantisation (temperatures over
-50..150 degC, angle over -pi..pi).

The bag is written by the embedded runtime and :class:`sma_wrist.bag.BagRecorder`: one node
publishes, at every 10 ms tick of the virtual clock, ``/clock``, both temperatures and
``/wrist/joint_states`` (header stamp = sample time), then both TEM commands (the command
that drives the next interval, as plant_sim's graph does); ``/wrist/payload`` is latched
once; the TEMs' exchanger faces where the Truth has them (``faces_start_C``). ``corrupt=`` makes bad bags for the
input checks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.signal import lfilter

from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.diagnose import effects as fx
from sma_wrist.diagnose.kernels import Constants

if TYPE_CHECKING:
    from sma_wrist.diagnose.data import Run

#: magnitude ranges of injected effects: param -> (low, high, random sign)
RANGES: dict[str, dict[str, tuple[float, float, bool]]] = {
    'sensor_delay': {'angle_delay_s': (0.15, 0.6, False)},
    'sensor_lag': {'temp_lag_s': (1.0, 4.0, False)},
    'sensor_offset_gain': {'angle_offset_rad': (0.02, 0.06, True), 'angle_gain_err': (0.04, 0.10, True)},
    'temp_sensor_offset': {'temp_offset_C': (1.0, 3.0, True)},
    'ambient_drift': {'ambient_drift_C_per_h': (8.0, 20.0, True)},
    'thermal_coupling': {'coupling_per_s': (0.008, 0.03, False)},
    'tem_mismatch': {'tem_gain_err': (0.08, 0.2, True)},
    'actuator_delay': {'command_delay_s': (0.1, 0.4, False)},
    'payload_mismatch': {'payload_err_kg': (0.1, 0.25, True)},
    'friction': {'coulomb_Nm': (0.03, 0.08, False)},
    'viscous_damping': {'viscous_Nms': (2.0, 6.0, False)},
    'backlash': {'backlash_rad': (0.02, 0.06, False)},
    'hysteresis_rate': {'hyst_lag_s': (4.0, 12.0, False)},
    'hysteresis_drift': {'hyst_drift_C_per_cycle': (1.5, 4.0, True)},
    'hysteresis_shift': {'hyst_shift_C': (2.0, 6.0, True)},
    'recalibrate_thermal': {'loss_scale_err': (0.12, 0.25, True)},
    'recalibrate_mechanics': {'preload_err_mm': (0.08, 0.2, True)},
    # per-channel sensors and the TEM driver
    'temp_sensor_offsets': {'temp_offset_1_C': (1.5, 3.0, True), 'temp_offset_2_C': (0.5, 1.2, True)},
    'temp_sensor_gain': {'temp_gain_err_1': (0.04, 0.1, True), 'temp_gain_err_2': (0.04, 0.1, True)},
    'temp_sensor_delay': {'temp_delay_1_s': (0.4, 1.5, False), 'temp_delay_2_s': (0.4, 1.5, False)},
    'temp_sensor_lags': {'temp_lag_1_s': (2.0, 5.0, False), 'temp_lag_2_s': (0.5, 1.0, False)},
    'temp_sensor_drift': {'temp_drift_1_C_per_h': (8.0, 25.0, True), 'temp_drift_2_C_per_h': (8.0, 25.0, True)},
    'angle_sensor_lag': {'angle_lag_s': (0.15, 0.5, False)},
    'angle_sensor_drift': {'angle_drift_rad_per_h': (0.1, 0.4, True)},
    'tem_dead_zone': {'tem_dead_zone_V': (1.0, 3.0, False)},
    'tem_saturation': {'tem_headroom_V': (12.0, 13.0, False)},  # the commands reach 13.5 V of the 24 V rating
}
NOISE_T_C = 0.05
NOISE_Q_RAD = 5e-4
ADC_BITS = 16
T_SPAN_C = (-50.0, 150.0)
Q_SPAN_RAD = (-np.pi, np.pi)
SUBSTEPS = 5


@dataclass
class Truth:
    """What was injected, and the sampled signals."""

    effect: str  # catalogue id or 'none'
    params: dict[str, float]
    seed: int
    payload_kg: float  # recorded payload (the true one differs under payload_mismatch)
    dt: float
    t: np.ndarray
    u: np.ndarray
    T: np.ndarray  # measured
    q: np.ndarray  # measured
    T_true: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    q_true: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    #: (K, 2) the TEMs' exchanger faces [degC] (published as /wrist/tem_{1,2}/face_temperature), or None: not recorded
    faces: np.ndarray | None = field(repr=False, default=None)


def commands(duration_s: float, dt: float, rng: np.random.Generator) -> np.ndarray:
    """Smooth random antagonistic TEM commands (K, 2) [V]."""
    K = int(round(duration_s / dt)) + 1
    s = np.empty(K)
    k = 0
    sign = 1.0 if rng.random() < 0.5 else -1.0
    while k < K:
        n = int(rng.uniform(45.0, 105.0) / dt)
        s[k : k + n] = sign
        sign = -sign
        k += n
    a = dt / 3.0
    s = lfilter([a], [1.0, a - 1.0], s, zi=[(1 - a) * s[0]])[0]
    hot1, hot2 = rng.uniform(12.0, 13.5, 2)
    u1 = np.where(s > 0, hot1 * s, 12.0 * s)
    u2 = np.where(s < 0, -hot2 * s, -12.0 * s)
    u = np.stack([u1, u2], axis=1)
    return np.clip(u + rng.normal(0.0, 0.3, (1, 2)), -12.0, 13.5)


def sample_params(effect: str, rng: np.random.Generator) -> dict[str, float]:
    if effect == 'none':
        return {}
    out = {}
    for name, (lo, hi, signed) in RANGES[effect].items():
        v = rng.uniform(lo, hi)
        if signed and rng.random() < 0.5:
            v = -v
        out[name] = float(v)
    return out


def quantise(x: np.ndarray, span: tuple[float, float], bits: int = ADC_BITS) -> np.ndarray:
    lsb = (span[1] - span[0]) / (2**bits)
    return np.clip(np.round((x - span[0]) / lsb) * lsb + span[0], *span)


def simulate(
    effect: str = 'none',
    seed: int = 0,
    duration_s: float = 240.0,
    params: dict[str, float] | None = None,
    payload_kg: float | None = None,
    dt: float = 0.01,
    u: np.ndarray | None = None,
    faces_start_C: tuple[float, float] | None = None,
) -> Truth:
    """The measured signals of one synthetic run (no bag); ``u``: (K, 2) TEM commands [V] instead of
    :func:`commands`' (K = duration_s / dt + 1). ``faces_start_C``: the TEMs' exchanger faces start there instead of
    at rest (a run after an excitation), and the Truth carries their trace (``faces``, recorded by write_bag)."""
    if effect != 'none' and effect not in fx.EFFECTS:
        raise ValueError(f'unknown effect {effect!r}; catalogue: {", ".join(fx.EFFECTS)}')
    rng = np.random.default_rng(seed)
    payload = float(rng.uniform(0.2, 0.5)) if payload_kg is None else float(payload_kg)
    injected = sample_params(effect, rng) if params is None else dict(params)
    r = fx.theta(**injected)
    consts = Constants(PlantParams(dt=dt))
    u = commands(duration_s, dt, rng) if u is None else np.asarray(u, float)
    K = u.shape[0]
    coef, drift, off = fx.thermal_coef(consts, r[[fx.INDEX[k] for k in fx.THERMAL_KEYS]])
    x0 = th.rest_state(consts.params.thermal, 1)
    x0 = x0 + off  # the ambient offset moves the rest state by exactly off
    if faces_start_C is not None:
        x0[..., th.EXCHANGER_FACE] = faces_start_C
    u_applied = fx.drive(
        fx.delayed(u, r[fx.INDEX['command_delay_s']], dt),
        r[fx.INDEX['tem_dead_zone_V']],
        r[fx.INDEX['tem_headroom_V']],
        consts.u_limits[1],
    )
    T_true, _ = consts.thermal(u_applied, dt, coef, x0, np.array([drift]), SUBSTEPS)
    T_true = T_true[:, 0]
    faces = None if faces_start_C is None else _face_trace(consts, u_applied, dt, coef, x0, drift)
    T_wire = (
        fx.first_order(T_true, r[fx.INDEX['hyst_lag_s']], dt)
        - r[fx.INDEX['hyst_shift_C']]
        - r[fx.INDEX['hyst_drift_C_per_cycle']] * fx.cycle_count(T_true, dt)
    )
    jr = consts.joint_row.copy()
    jr[0] = r[fx.INDEX['coulomb_Nm']]
    jr[1] = r[fx.INDEX['viscous_Nms']]
    jr[2] = fx.STATIC_PER_COULOMB * jr[0]
    jr[3] += r[fx.INDEX['preload_err_mm']]
    jr[4] = payload + r[fx.INDEX['payload_err_kg']]
    q_true, _, _ = consts.mechanics(T_wire[:, None, :], dt, jr, SUBSTEPS)
    q_true = q_true[:, 0]
    # sensors
    model = fx.ExtendedModel.__new__(fx.ExtendedModel)
    model.dt = dt
    model.consts = consts
    q_meas = fx.ExtendedModel.angle_sensor(model, q_true, r)
    T_meas = fx.thermocouples(T_true, r, dt)
    q_meas = quantise(q_meas + rng.normal(0.0, NOISE_Q_RAD, K), Q_SPAN_RAD)
    T_meas = quantise(T_meas + rng.normal(0.0, NOISE_T_C, (K, 2)), T_SPAN_C)
    t = np.arange(K) * dt
    if faces is not None:
        faces = quantise(faces + rng.normal(0.0, NOISE_T_C, (K, 2)), T_SPAN_C)
    return Truth(effect, injected, seed, payload, dt, t, u, T_meas, q_meas, T_true, q_true, faces)


def _face_trace(
    consts: Constants, u: np.ndarray, dt: float, coef: np.ndarray, x0: np.ndarray, drift: float, chunk: int = 10
) -> np.ndarray:
    """(K, 2) exchanger faces [degC] of the heat balance from x0 (the kernel returns the muscle faces only, and
    its final state): the state at every ``chunk``-th sample, interpolated between."""
    if drift:
        raise ValueError('exchanger-face traces are simulated without an ambient drift')
    K = u.shape[0]
    ks, xs = [0], [x0[0, :, th.EXCHANGER_FACE].copy()]
    x = x0
    for a in range(0, K - 1, chunk):
        b = min(a + chunk, K - 1)
        _, x = consts.thermal(u[a : b + 1], dt, coef, x, np.zeros(1), SUBSTEPS)
        ks.append(b)
        xs.append(x[0, :, th.EXCHANGER_FACE].copy())
    xs_a = np.array(xs)
    return np.stack([np.interp(np.arange(K), ks, xs_a[:, i]) for i in range(2)], axis=1)


def run_from_truth(truth: Truth) -> Run:
    """The Run that :func:`sma_wrist.diagnose.data.load_run` makes of ``write_bag(truth)``, without the bag.

    Sweeps (the benchmark, most tests) use it: same arrays, no recording cost.
    """
    from sma_wrist.diagnose.data import Run

    return Run(
        t=truth.t.copy(),
        dt=truth.dt,
        u=truth.u.copy(),
        T=truth.T.copy(),
        q=truth.q.copy(),
        payload_kg=truth.payload_kg,
        source=f'synthetic {truth.effect} seed {truth.seed}',
    )


# ----------------------------------------------------------------------------- bags
def write_bag(
    truth: Truth,
    path: str | Path,
    corrupt: dict[str, Any] | None = None,
    nodes: Sequence[type] = (),
    params: dict[str, dict[str, Any]] | None = None,
    applied: np.ndarray | None = None,
) -> Path:
    """Write a Truth as a rosbag2 (MCAP) bag through the embedded runtime and BagRecorder.

    ``applied``: (K, 2) [V] the drive the device read back, published on /wrist/tem_drive_applied (as
    hardware_bridge does) with each sample's stamp, as the drive that held from there (the commands' convention).

    ``nodes``: node classes that run beside the publisher (they see the data live and their topics are recorded
    too, e.g. twin_monitor), with ``params`` ({node: {name: value}}).

    corrupt: {'drop_topics': [...], 'nan_T': (start, n), 'kelvin': True, 'degrees': True,
    'gap': (start_s, length_s), 'shuffle_stamps': n, 'duplicate_stamps': n, 'stamp_jitter_s': sigma (white
    jitter of the header stamps, clipped to +-0.4 of a sample), 'drop_rate': p (each measurement message lost
    with probability p)}.
    """
    from sma_wrist import runtime

    runtime.activate()
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, QoSProfile
    from rclpy.time import Time
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState, Temperature
    from std_msgs.msg import Float64

    from sma_wrist.runtime.launch import run_nodes

    c = dict(corrupt or {})
    drop = set(c.get('drop_topics', ()))
    K = truth.t.size
    T = truth.T.copy()
    q = truth.q.copy()
    if 'nan_T' in c:
        a, n = c['nan_T']
        T[a : a + n, 0] = np.nan
    if c.get('kelvin'):
        T = T + 273.15
    if c.get('degrees'):
        q = np.rad2deg(q)
    skip = np.zeros(K, bool)
    if 'gap' in c:
        a, n = c['gap']
        skip[int(a / truth.dt) : int((a + n) / truth.dt)] = True
    stamp_ns = (np.arange(K) + 1) * int(round(truth.dt * 1e9))
    head = stamp_ns.copy()
    rng = np.random.default_rng(truth.seed + 7)
    if c.get('shuffle_stamps'):
        i = rng.choice(np.arange(1, K - 1), c['shuffle_stamps'], replace=False)
        head[i], head[i + 1] = head[i + 1].copy(), head[i].copy()
    if c.get('duplicate_stamps'):
        i = rng.choice(np.arange(1, K - 1), c['duplicate_stamps'], replace=False)
        head[i] = head[i - 1]
    if c.get('stamp_jitter_s'):
        lim = 0.4 * truth.dt * 1e9
        head = head + np.clip(rng.normal(0.0, c['stamp_jitter_s'] * 1e9, K), -lim, lim).astype(np.int64)
    lost = rng.random((K, 3)) < c.get('drop_rate', 0.0)  # T1, T2, joint
    u = truth.u
    payload = truth.payload_kg

    class Measured(Node):
        def __init__(self) -> None:
            super().__init__('measured_wrist')
            self.k = 0
            self.pub = {}
            for name, typ in (
                ('/clock', Clock),
                ('/wrist/muscle_1/temperature', Temperature),
                ('/wrist/muscle_2/temperature', Temperature),
                ('/wrist/joint_states', JointState),
                ('/wrist/tem_1/command', Float64),
                ('/wrist/tem_2/command', Float64),
            ):
                if name not in drop:
                    self.pub[name] = self.create_publisher(typ, name, 10)
            if '/wrist/payload' not in drop:
                latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
                self.create_publisher(Float64, '/wrist/payload', latched).publish(Float64(data=payload))
            if applied is not None:
                self.drive_pub = self.create_publisher(JointState, '/wrist/tem_drive_applied', 10)
            for i in (1, 2):
                name = f'/wrist/tem_{i}/face_temperature'
                if truth.faces is not None and name not in drop:
                    self.pub[name] = self.create_publisher(Temperature, name, 10)
            self.create_timer(truth.dt, self.tick)

        def tick(self) -> None:
            k = self.k
            if k >= K:
                return
            self.k += 1
            if skip[k]:
                return
            p = self.pub
            stamp = Time(nanoseconds=int(head[k])).to_msg()
            if '/clock' in p:
                p['/clock'].publish(Clock(clock=Time(nanoseconds=int(stamp_ns[k])).to_msg()))
            for i in (1, 2):
                name = f'/wrist/muscle_{i}/temperature'
                if name in p and not lost[k, i - 1]:
                    m = Temperature(temperature=float(T[k, i - 1]), variance=NOISE_T_C**2)
                    m.header.stamp = stamp
                    m.header.frame_id = f'muscle_{i}'
                    p[name].publish(m)
            for i in (1, 2):
                name = f'/wrist/tem_{i}/face_temperature'
                if name in p:
                    m = Temperature(temperature=float(truth.faces[k, i - 1]), variance=NOISE_T_C**2)
                    m.header.stamp = stamp
                    m.header.frame_id = f'tem_{i}'
                    p[name].publish(m)
            if '/wrist/joint_states' in p and not lost[k, 2]:
                js = JointState(name=['wrist'], position=[float(q[k])], velocity=[0.0], effort=[0.0])
                js.header.stamp = stamp
                js.header.frame_id = 'wrist_base'
                p['/wrist/joint_states'].publish(js)
            for i in (1, 2):
                name = f'/wrist/tem_{i}/command'
                if name in p:
                    p[name].publish(Float64(data=float(u[k, i - 1])))
            if applied is not None:
                d = JointState(name=['tem_1', 'tem_2'], effort=[float(applied[k, 0]), float(applied[k, 1])])
                d.header.stamp = Time(nanoseconds=int(stamp_ns[k])).to_msg()
                d.header.frame_id = 'wrist_base'
                self.drive_pub.publish(d)

    path = Path(path)
    try:
        run_nodes(
            [Measured, *nodes], duration=K * truth.dt + 0.5 * truth.dt, bag=str(path), until='steady', params=params
        )
    finally:
        rclpy.try_shutdown()
    return path


def write_run_bag(
    run: Run,
    path: str | Path,
    corrupt: dict[str, Any] | None = None,
    seed: int = 0,
    nodes: Sequence[type] = (),
    params: dict[str, dict[str, Any]] | None = None,
) -> Path:
    """Write an aligned Run (e.g. a recording rewritten by :mod:`.distort`) as a bag, like :func:`write_bag`."""
    truth = Truth('recorded', {}, seed, run.payload_kg, run.dt, run.t, run.u, run.T, run.q)
    return write_bag(truth, path, corrupt, nodes, params)


def make_bag(
    path: str | Path,
    effect: str = 'none',
    seed: int = 0,
    duration_s: float = 240.0,
    corrupt: dict[str, Any] | None = None,
    **kw: Any,
) -> Truth:
    """simulate + write_bag; returns the Truth (injected effect and parameters)."""
    truth = simulate(effect, seed, duration_s, **kw)
    write_bag(truth, path, corrupt)
    return truth
