"""The plant model a ROS 2 params file describes: what ``sma-wrist diagnose --params-file`` replays and what the
twin monitor simulates.

A params file (``{node: {ros__parameters: {...}}}``) describes the plant in the section of the node that runs it:
``plant_sim`` (the simulated wrist), else ``hardware_bridge`` (the real one, whose model its calibration and the
controllers share). Of that section the model is

* ``hysteresis_file`` (the wire's SD-GPI, ``sma-wrist identify``; empty: the built-in set),
* ``thermal_file`` (the TEMs' heat balance, ``sma-wrist identify thermal``; empty: Table 4.9),
* ``heat_balance_file`` (the model's heat balance in another form than Table 4.9's, the Peltier two-node form
  ``sma-wrist commission`` hands over where it predicts better; empty: Table 4.9's form of ``thermal_file``),
* ``wire_file`` (the model's wire where it is not that SD-GPI: ``wire.yaml``, a phase-fraction wire that
  ``sma-wrist commission`` hands over; empty: the SD-GPI of ``hysteresis_file``),
* ``preload_elongation_mm`` (the chain's pre-load, Eq. 4.17; absent: the built-in 1.98 mm),
* ``model.<name>`` (the extension parameters of :mod:`sma_wrist.core.plant.extensions`, e.g. the commissioned
  ``model.coulomb_Nm``; absent: nominal),
* ``payload_kg`` (the payload the run believes; informative).

Relative model file paths are resolved against the params file's folder: ``sma-wrist commission`` writes
``wrist_params.yaml`` next to the ``hysteresis.yaml`` and ``thermal.yaml`` it names, and the hand-over folder may be
moved as a whole. One file holds both a commissioned wrist (``wrist_params.yaml``: plant_sim, hardware_bridge,
controllers) and a diagnosis' ``extended_params.yaml`` (one plant_sim section with the fitted ``model.*`` values).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.plant import extensions as mx
from sma_wrist.core.plant.wrist import PlantParams

#: the nodes whose section describes the plant, in the order they are looked for
PLANT_NODES = ('plant_sim', 'hardware_bridge')
#: the model files a plant node names: key, what writes one
MODEL_FILES = (
    ('hysteresis_file', 'sma-wrist identify hysteresis (or sma-wrist commission) writes one'),
    ('thermal_file', 'sma-wrist identify thermal (or sma-wrist commission) writes one'),
    ('heat_balance_file', 'sma-wrist commission writes one where the Peltier form predicts better'),
    ('wire_file', 'sma-wrist commission writes one (wire.yaml)'),
)


class PlantModelFileError(ParameterError):
    """A params file does not describe a plant model: the message names the file, the key and what to do."""


@dataclass(frozen=True)
class PlantModel:
    """The plant model of a params file's plant node (see the module docstring)."""

    source: str  # the params file ('' when only model files were given)
    node: str  # the section read ('' likewise)
    hysteresis_file: str | None = None  # absolute, or None for the built-in wire
    thermal_file: str | None = None  # absolute, or None for Table 4.9
    heat_balance_file: str | None = None  # absolute, or None for Table 4.9's form of the thermal file
    wire_file: str | None = None  # absolute, or None for the SD-GPI of hysteresis_file
    preload_elongation_mm: float | None = None  # None: PlantParams' built-in pre-load
    #: the ``model.*`` values the file gives {name: value} (extensions.PARAMS names), validated
    extension: dict[str, float] = field(default_factory=dict)
    payload_kg: float | None = None

    def base(self, **fields: Any) -> PlantParams:
        """The plain plant (no ``model.*``): the model files and the pre-load (``fields``: other PlantParams
        fields, e.g. ``dt``). Raises PlantModelFileError naming a model file that does not load."""
        if self.preload_elongation_mm is not None:
            fields = {'preload_elongation_mm': self.preload_elongation_mm, **fields}
        try:
            return PlantParams.from_files(
                self.hysteresis_file,
                self.thermal_file,
                heat_balance_file=self.heat_balance_file,
                wire_file=self.wire_file,
                **fields,
            )
        except Exception as exc:  # noqa: BLE001 - a broken model file is the user's to fix, said in one line
            raise PlantModelFileError(
                f'{self._where()}model files do not load ({type(exc).__name__}: {exc}); write them with '
                f'sma-wrist identify (hysteresis / thermal) or sma-wrist commission'
            ) from None

    def params(self, simulated_only: bool = False, **fields: Any) -> PlantParams:
        """The plant plant_sim runs from this model: :meth:`base` with the ``model.*`` extension folded in
        (:func:`sma_wrist.core.plant.extensions.plant_params`). ``simulated_only``: the effects the plant does not
        simulate (:data:`~sma_wrist.core.plant.extensions.REPLAY_ONLY`, which plant_sim refuses) left at nominal,
        as a twin of the wrist must."""
        ext = {k: v for k, v in self.extension.items() if not (simulated_only and k in mx.REPLAY_ONLY)}
        try:
            return mx.plant_params(ext, self.base(**fields))
        except PlantModelFileError:
            raise
        except ParameterError as exc:
            raise PlantModelFileError(f'{self._where()}{exc}') from None

    def describe(self) -> str:
        """One line: what the model is made of (the params file's node, model files, pre-load, ``model.*`` values)."""
        parts = [f'{self.node} of {self.source}'] if self.source else []
        parts += [
            f'{k} {v}'
            for k, v in (
                ('hysteresis_file', self.hysteresis_file),
                ('thermal_file', self.thermal_file),
                ('heat_balance_file', self.heat_balance_file),
                ('wire_file', self.wire_file),
            )
            if v
        ]
        if self.preload_elongation_mm is not None:
            parts.append(f'preload_elongation_mm {self.preload_elongation_mm:g}')
        parts += [f'model.{k} {v:g}' for k, v in self.extension.items()]
        return ', '.join(parts) or 'the built-in model'

    def _where(self) -> str:
        return f'params file {self.source} ({self.node}): ' if self.source else ''


def _model_file(value: Any, key: str, how: str, folder: Path | None, where: str) -> str | None:
    """An existing model file's absolute path ('' or None: the built-in model). A relative name is looked up in
    ``folder`` (the params file's) first, then in the working folder, where the nodes look for it: a params file
    written as ``runs/x/wrist_params.yaml`` names its files ``runs/x/...`` (relative to where it was written)."""
    if value is None or value == '':
        return None
    if not isinstance(value, str):
        raise PlantModelFileError(f'{where}{key} must be a file name, got {value!r}')
    p = Path(value).expanduser()
    tried = [p]
    if folder is not None and not p.is_absolute():
        tried = [folder / p, p]
    for c in tried:
        if c.is_file():
            return str(c.resolve())
    raise PlantModelFileError(f'{where}{key} {" or ".join(map(str, tried))}: no such file ({how})')


def declared_parameters(node: str) -> set[str]:
    """The parameter names ``node`` (one of :data:`PLANT_NODES`) declares."""
    from sma_wrist import runtime

    runtime.activate()  # the node modules import the message types (the embedded runtime's where rclpy is absent)
    if node == 'plant_sim':
        from sma_wrist.nodes.plant_sim import PlantSim as cls
    else:
        from sma_wrist.nodes.hardware_bridge import HardwareBridge as cls
    return {p.name for p in cls.PARAMS} | {'use_sim_time'}


def plant_section(path: str | Path) -> tuple[str, dict[str, Any]]:
    """(node, {parameter: value}) of the plant node of a params file, as the node would get them (rcl's rules:
    ``/ns/plant_sim`` is plant_sim, ``/**`` applies to every node, nested keys are dotted names). Raises
    PlantModelFileError for a file that does not parse, that has no plant node section or whose plant node
    section has a key that node does not declare."""
    from sma_wrist.runtime.arguments import load_params_file
    from sma_wrist.runtime.errors import ArgumentError

    try:
        rules = load_params_file(path)
    except ArgumentError as exc:
        raise PlantModelFileError(f'params file {path}: not a ROS 2 params file ({exc.what})') from None
    nodes = [r.node.strip('/') for r in rules]
    own = [n.rsplit('/', 1)[-1] for n in nodes]
    node = next((n for n in PLANT_NODES if n in own), None)
    if node is None:
        named = sorted({r.node for r in rules})
        raise PlantModelFileError(
            f'params file {path}: no plant node section ({" or ".join(PLANT_NODES)}; it has '
            f'{", ".join(named) or "none"}); sma-wrist commission and sma-wrist diagnose --params write one'
        )
    declared = declared_parameters(node)
    values: dict[str, Any] = {}
    unknown = []
    for r, n, o in zip(rules, nodes, own):
        if o == node:
            if r.name not in declared:
                unknown.append(r.name)
            values[r.name] = r.value
        elif n in ('**', '*') and r.name in declared:
            values[r.name] = r.value
    model_unknown = [k for k in unknown if k.startswith('model.')]
    if unknown:
        raise PlantModelFileError(
            f'params file {path} ({node}): {node} has no parameter {", ".join(unknown)}'
            + (f' (the model.* parameters: {", ".join(mx.BY_NAME)})' if model_unknown else '')
        )
    return node, values


def read_plant_model(
    params_file: str | Path | None = None,
    hysteresis_file: str | None = None,
    thermal_file: str | None = None,
    heat_balance_file: str | None = None,
    wire_file: str | None = None,
) -> PlantModel:
    """The plant model of ``params_file``'s plant node; explicit ``hysteresis_file`` / ``thermal_file`` (relative to
    the working directory) replace the file's. Without a params file: the model files alone (or the built-in
    model). Raises PlantModelFileError for a file without a plant node section, an unknown or out-of-range
    ``model.*`` key, a pre-load that is not a number, or a model file that does not exist."""
    explicit = {
        key: _model_file(f, key, how, None, '')
        for (key, how), f in zip(MODEL_FILES, (hysteresis_file, thermal_file, heat_balance_file, wire_file))
    }
    if not params_file:
        return PlantModel('', '', **explicit)
    src = str(params_file)
    path = Path(params_file).expanduser()
    if not path.is_file():
        raise PlantModelFileError(
            f'params file {src}: no such file (sma-wrist commission or sma-wrist diagnose --params writes one)'
        )
    node, values = plant_section(path)
    where = f'params file {src} ({node}): '
    files = {
        key: explicit[key] or _model_file(values.get(key), key, how, path.parent, where) for key, how in MODEL_FILES
    }
    numbers: dict[str, float] = {}
    for key in ('preload_elongation_mm', 'payload_kg'):
        v = values.get(key)
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise PlantModelFileError(f'{where}{key} must be a finite number, got {v!r}')
        numbers[key] = float(v)
    ext: dict[str, float] = {}
    for k, v in values.items():
        if str(k).startswith('model.'):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise PlantModelFileError(f'{where}{k} must be a number, got {v!r}')
            ext[str(k)[6:]] = float(v)
    try:
        mx.check(ext)
    except ParameterError as exc:
        raise PlantModelFileError(f'{where}{exc}') from None
    return PlantModel(src, node, extension=ext, **files, **numbers)  # type: ignore[arg-type]
