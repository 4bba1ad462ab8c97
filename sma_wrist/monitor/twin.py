"""The digital twin of a running wrist: the plant model driven by the TEM drive (the device's read-back, else the
commands).

:class:`Twin` steps :class:`sma_wrist.core.plant.wrist.WristPlant` (the plant ``plant_sim`` runs, at its 1 kHz
step) over each interval between two measurement stamps under the command held over it (in batches of intervals) (the command stamped at
t_k drives [t_k, t_k+1), plant_sim's convention and the diagnosis'). Its predictions are what the wrist would read
if it were its model; its heat-balance state at the start of a check window is where the diagnosis' thermal replay
of that window starts (:attr:`sma_wrist.diagnose.data.Run.thermal_x0`), because a window cut from the middle of a
run does not start with its heat exchangers at rest.

:func:`load_model` builds the model from the files a user has: the identified wire (``hysteresis_file``), the
identified TEMs (``thermal_file``), or a params file: the model of its plant node (a commissioned
``wrist_params.yaml``: model files, pre-load, ``model.*`` values; a diagnosis' ``extended_params.yaml``: its fitted
``model.*`` extension), read by :func:`sma_wrist.plant_model.read_plant_model` as ``sma-wrist diagnose`` reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.plant.wrist import PlantParams, WristPlant
from sma_wrist.core.thermal import heat_balance as th


class MonitorInputError(SmaWristError):
    """The monitor cannot run: the message names what is missing or wrong and how to get it."""


@dataclass
class Model:
    """What the twin simulates and what the monitor expects to see."""

    params: PlantParams
    #: a diagnosis' extended model {name: value} (sma_wrist.core.plant.extensions names), {} for the plain model:
    #: a verdict naming these parameters near these values is the known wrist, not a new discrepancy
    extension: dict[str, float] = field(default_factory=dict)
    hysteresis_file: str | None = None
    thermal_file: str | None = None
    payload_err_kg: float = 0.0
    description: str = 'the built-in model'
    #: the params file the model is read from: the checks' diagnosis replays its model (pre-load, model.* values)
    params_file: str | None = None


def load_model(
    hysteresis_file: str | None = None, thermal_file: str | None = None, params_file: str | None = None
) -> Model:
    """The twin's model: that of ``params_file``'s plant node (:func:`sma_wrist.plant_model.read_plant_model`: a
    commissioned ``wrist_params.yaml`` or a diagnosis' ``extended_params.yaml``), the explicit model files replacing
    its; raises MonitorInputError naming what does not load and how to make it."""
    from sma_wrist.core.plant import extensions as mx
    from sma_wrist.plant_model import PlantModelFileError, read_plant_model

    try:
        pm = read_plant_model(params_file, hysteresis_file, thermal_file)
        # the twin simulates what plant_sim can; the replay-only effects stay the diagnosis' known extension
        params = pm.params(simulated_only=True)
    except PlantModelFileError as exc:
        raise MonitorInputError(str(exc)) from None
    return Model(
        params,
        {k: v for k, v in pm.extension.items() if v != mx.NOMINAL[k]},
        pm.hysteresis_file,
        pm.thermal_file,
        float(pm.extension.get('payload_err_kg', 0.0)),
        pm.describe(),
        str(params_file) if params_file else None,
    )


class Twin:
    """The model wrist stepped beside the real one (``plant_sim``'s plant, no sensor effects).

    The samples' intervals are queued and stepped in batches (:meth:`WristPlant.advance_segments`, one compiled call
    per batch) when a prediction is read or :data:`BATCH` have queued: stepped one call per 100 Hz sample, the twin
    was most of the monitor's own work (the call overhead, not the 10 plant steps). The heat-balance state after every
    interval is kept (:meth:`thermal_state_at`) for the checks' windows."""

    #: intervals queued before they are stepped without being asked for
    BATCH = 100

    def __init__(self, model: Model, payload_kg: float) -> None:
        self.model = model
        self.payload_kg = float(payload_kg)
        self._plant = WristPlant(model.params, payload_kg=max(self.payload_kg + model.payload_err_kg, 0.0))
        self.t: float | None = None  # stamp of the state [s] (queued intervals included)
        self.command_V = np.zeros((1, 2))
        self._queue_u: list[tuple[float, float]] = []
        self._queue_n: list[int] = []
        self._queue_t: list[float] = []
        # heat-balance states after each stepped interval: chunks of stamps (K,) [s] and states (K, 2, 2) [degC]
        self._log_t: list[np.ndarray] = []
        self._log_x: list[np.ndarray] = []
        self._log_q: list[np.ndarray] = []  # angles [rad] at the same stamps (the residuals' change point)

    def set_payload(self, payload_kg: float) -> None:
        """The recorded payload changed (``/wrist/payload``): the twin carries the new mass from now on."""
        self.flush()
        self.payload_kg = float(payload_kg)
        self._plant.state.payload_kg[:] = max(self.payload_kg + self.model.payload_err_kg, 0.0)

    def set_command(self, i: int, volts: float) -> None:
        """TEM ``i`` (0, 1) was commanded ``volts`` [V]; it drives the twin from the next measurement stamp on."""
        self.command_V[0, i] = volts

    def set_thermal_state(self, x: np.ndarray) -> None:
        """Put the heat balance at the measured state ``x`` (2 muscles, [muscle face, exchanger face]) [degC] at the
        twin's stamp: a wrist whose TEMs start warm (after an excitation) is followed from where it is, not from rest
        (the exchangers' time constant is minutes)."""
        self.flush()
        self._plant.state.thermal[0] = np.asarray(x, dtype=float)
        if self._log_x:  # the state logged at this stamp is the measured one
            self._log_x[-1][-1] = self._plant.state.thermal[0]

    def advance_to(self, t_s: float) -> None:
        """Integrate to the measurement stamp ``t_s`` [s] under the held commands (steps of the plant's dt; queued)."""
        if self.t is None:
            self.t = t_s
            self._log_t.append(np.array([t_s]))
            self._log_x.append(np.array(self._plant.state.thermal[:1], dtype=float))
            self._log_q.append(np.array(self._plant.state.q[:1], dtype=float))
            return
        if t_s <= self.t:
            return
        n = int(round((t_s - self.t) / self.model.params.dt))
        if n > 0:
            # a stamp far ahead (a pause of the recording) is integrated too: the plant went on meanwhile
            self.t += n * self.model.params.dt
            self._queue_u.append((float(self.command_V[0, 0]), float(self.command_V[0, 1])))
            self._queue_n.append(n)
            self._queue_t.append(self.t)
            if len(self._queue_n) >= self.BATCH:
                self.flush()

    def flush(self) -> None:
        """Step the queued intervals (one compiled call) and log the heat-balance state after each."""
        if not self._queue_n:
            return
        u = np.array(self._queue_u, dtype=float)[:, None, :]
        thermal, q, _ = self._plant.advance_segments(u, np.array(self._queue_n, dtype=np.int64))
        self._log_t.append(np.array(self._queue_t))
        self._log_x.append(thermal[:, 0])
        self._log_q.append(q[:, 0])
        self._queue_u.clear()
        self._queue_n.clear()
        self._queue_t.clear()

    def thermal_state_at(self, t_s: float) -> np.ndarray:
        """Heat-balance state (2 layers, 2 faces) [degC] of the last stepped stamp at or before ``t_s`` [s] (the
        first one kept, for an earlier ``t_s``)."""
        self.flush()
        ts = np.concatenate(self._log_t)
        j = int(np.clip(np.searchsorted(ts, t_s + 1e-9) - 1, 0, ts.size - 1))
        return np.concatenate(self._log_x)[j].copy()

    def trim(self, t_min: float) -> None:
        """Forget the logged states before ``t_min`` [s] (keeping the last one before it)."""
        self.flush()
        if not self._log_t:
            return
        ts, xs, qs = np.concatenate(self._log_t), np.concatenate(self._log_x), np.concatenate(self._log_q)
        n = max(int(np.searchsorted(ts, t_min)) - 1, 0)
        self._log_t, self._log_x, self._log_q = [ts[n:]], [xs[n:]], [qs[n:]]

    def predictions(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The twin's stamps [s], muscle temperatures (K, 2) [degC] and angles (K,) [rad] logged in [lo, hi]."""
        self.flush()
        ts = np.concatenate(self._log_t)
        sel = (ts >= lo) & (ts <= hi)
        x = np.concatenate(self._log_x)[sel]
        T = th.muscle_temperature(self.model.params.thermal, x) if x.size else np.empty((0, 2))
        return ts[sel], np.asarray(T, dtype=float), np.concatenate(self._log_q)[sel]

    @property
    def plant(self) -> WristPlant:
        """The model wrist, stepped to :attr:`t`."""
        self.flush()
        return self._plant

    @property
    def temperatures_C(self) -> np.ndarray:
        """Predicted muscle temperatures (2,) [degC]."""
        return self.plant.muscle_temperature_C[0].copy()

    @property
    def angle_rad(self) -> float:
        """Predicted wrist angle [rad]."""
        return float(self.plant.state.q[0])

    @property
    def thermal_state(self) -> np.ndarray:
        """Heat-balance state (2 layers, 2 faces) [degC]."""
        return np.array(self.plant.state.thermal[0], dtype=float)

    def describe(self) -> dict[str, Any]:
        return {'model': self.model.description, 'payload_kg': self.payload_kg}
