"""The thermal params file: an identified TEM heat balance (Table 4.9 layout) the wrist loads.

``sma-wrist identify thermal`` writes it; ``plant_sim`` and ``tem_controller`` read it through
their ``thermal_file`` parameter with :func:`load_thermal_file` (the one loader), so the
simulated TEMs, the controller's feedback-linearising law (Eqs. 5.38-5.47), its observer and
its face protection all use the same identified model. Format (YAML, version 1)::

    format: sma_wrist/thermal
    version: 1
    input_per_volt: 0.4          # I = -input_per_volt * u (u [V], positive heats the muscle face)
    tem_gain: [0.8, 1.0]         # optional: TEM 1's and TEM 2's drive gain, I = -input_per_volt * tem_gain[l] * u
    muscle_face:                 # T1 column of Table 4.9, Eq. 4.13 [1/(s I), 1/s, degC/(s I^2), degC/s]
      K_alpha_tau: -0.004472
      K_tau: -0.004207
      K_T_inf: 0.052345
      K_T: 0.028312
      K_R: 0.012524
      K_inf: 0.615142
    exchanger_face: {...}        # T2 column, Eq. 4.14
    hold_limits_V: [-12.0, 13.0] # commands held forever keep every face in window_C (doc/explanation/model.md);
                                 # per TEM where they differ: [[TEM 1 low, high], [TEM 2 low, high]]
    window_C: [0.0, 80.0]
    identification: {...}        # provenance and held-out errors; informative only

Unknown top-level keys are rejected (a typo must not silently fall back to a default). ``tem_gain`` may be left
out (both modules alike, [1, 1]; it is written only where the modules differ, so such files read as before).
``hold_limits_V`` is one [low, high] pair for both TEMs, or one pair per TEM (written only where they differ: a
weaker TEM holds a larger drive, ThermalParams.tem_hold_limits_V); files with one pair read as before.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.yaml_file import write_yaml_file

FORMAT = 'sma_wrist/thermal'
VERSION = 1
FACE_KEYS = tuple(f.name for f in dataclasses.fields(th.FaceCoefficients))
_KEYS = {
    'format',
    'version',
    'input_per_volt',
    'tem_gain',
    'muscle_face',
    'exchanger_face',
    'hold_limits_V',
    'window_C',
    'identification',
}


def thermal_file_dict(params: th.ThermalParams, identification: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The file's content for ``params`` (effective K_inf, i.e. with ambient_C folded in)."""
    k_inf = params.K_inf
    faces = {}
    for i, (key, face) in enumerate((('muscle_face', params.muscle_face), ('exchanger_face', params.exchanger_face))):
        row = {k: float(getattr(face, k)) for k in FACE_KEYS}
        row['K_inf'] = float(k_inf[i])
        faces[key] = row
    gain = {} if params.tem_gain == (1.0, 1.0) else {'tem_gain': [float(g) for g in params.tem_gain]}
    return {
        'format': FORMAT,
        'version': VERSION,
        'input_per_volt': float(params.input_per_volt),
        **gain,
        **faces,
        'hold_limits_V': [float(params.u_min_V), float(params.u_max_V)]
        if params.tem_hold_limits_V is None
        else [[float(v) for v in pair] for pair in params.tem_hold_limits_V],
        'window_C': [float(params.window_C[0]), float(params.window_C[1])],
        'identification': dict(identification or {}),
    }


def write_thermal_file(
    path: str | Path, params: th.ThermalParams, identification: Mapping[str, Any] | None = None, header: str = ''
) -> Path:
    """Write ``params`` as a version-1 thermal file (YAML) with an optional comment header."""
    return write_yaml_file(path, thermal_file_dict(params, identification), header)


def _number(path: Path, where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ParameterError(f'{path}: {where} = {value!r} must be a finite number')
    return float(value)


def load_thermal_file(path: str | Path, base: th.ThermalParams | None = None) -> th.ThermalParams:
    """ThermalParams from a thermal file; other fields (dt_max_s, coupling) from ``base``.

    The command limits of the result are the file's hold limits (with one pair per TEM, what both hold; each TEM's
    in ``tem_hold_limits_V``). Raises ParameterError naming
    the file and what is wrong (missing, not YAML, wrong format/version, a missing, unknown or
    non-finite key, an inconsistent heat balance).
    """
    import yaml

    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text(encoding='utf-8'))
    except OSError as e:
        raise ParameterError(
            f'{p}: cannot read the thermal file ({e.strerror or e}); write one with '
            '`sma-wrist identify thermal ... --out DIR`'
        ) from None
    except UnicodeDecodeError as e:  # a binary file given by mistake
        raise ParameterError(
            f'{p}: not a UTF-8 text thermal file (byte {e.start}: {e.reason}); write one with '
            '`sma-wrist identify thermal ... --out DIR`'
        ) from None
    except yaml.YAMLError as e:
        raise ParameterError(f'{p}: not a YAML thermal file ({str(e).splitlines()[0]})') from None
    if not isinstance(data, dict) or data.get('format') != FORMAT:
        raise ParameterError(f'{p}: not a thermal file (need `format: {FORMAT}` at the top level)')
    if data.get('version') != VERSION:
        raise ParameterError(f'{p}: thermal file version {data.get("version")!r} is not supported (need {VERSION})')
    unknown = sorted(set(data) - _KEYS)
    if unknown:
        raise ParameterError(f'{p}: unknown key(s) {", ".join(map(str, unknown))}; known: {", ".join(sorted(_KEYS))}')
    faces = []
    for key in ('muscle_face', 'exchanger_face'):
        row = data.get(key)
        if not isinstance(row, dict) or set(row) != set(FACE_KEYS):
            raise ParameterError(f'{p}: {key} must map exactly {", ".join(FACE_KEYS)} to numbers')
        faces.append(th.FaceCoefficients(**{k: _number(p, f'{key}.{k}', row[k]) for k in FACE_KEYS}))
    gain = data.get('tem_gain', [1.0, 1.0])
    if not (isinstance(gain, list) and len(gain) == 2):
        raise ParameterError(f'{p}: tem_gain must be a [TEM 1, TEM 2] list of drive gains (> 0)')
    gains = (_number(p, 'tem_gain[0]', gain[0]), _number(p, 'tem_gain[1]', gain[1]))
    limits = data.get('hold_limits_V', [None, None])
    window = data.get('window_C', list((base or th.ThermalParams()).window_C))
    per_tem = isinstance(limits, list) and len(limits) == 2 and all(isinstance(q, list) for q in limits)
    pairs = limits if per_tem else [limits]
    if not (all(isinstance(q, list) and len(q) == 2 for q in pairs) and isinstance(window, list) and len(window) == 2):
        raise ParameterError(
            f'{p}: hold_limits_V must be a [low, high] list (or one per TEM: [[low, high], [low, high]]) and '
            'window_C a [low, high] list'
        )
    key = ['hold_limits_V[0]', 'hold_limits_V[1]'] if per_tem else ['hold_limits_V']
    held = [(_number(p, f'{key[k]}[0]', q[0]), _number(p, f'{key[k]}[1]', q[1])) for k, q in enumerate(pairs)]
    base = base or th.ThermalParams()
    try:
        params = dataclasses.replace(
            base,
            muscle_face=faces[0],
            exchanger_face=faces[1],
            ambient_C=None,
            input_per_volt=_number(p, 'input_per_volt', data.get('input_per_volt')),
            tem_gain=gains,
            window_C=(_number(p, 'window_C[0]', window[0]), _number(p, 'window_C[1]', window[1])),
        )
        return params.with_hold_limits((held[0], held[-1]))
    except ParameterError as e:
        raise ParameterError(f'{p}: {e}') from None


# ------------------------------------------------------------------------ the model's heat balance (another form)
#: the heat-balance file: the MODEL's heat balance where it is not Table 4.9's form (the node parameter
#: ``heat_balance_file``; empty: Table 4.9's form of ``thermal_file``). ``sma-wrist commission`` writes one where the
#: Peltier form predicts the held-out excitation better (doc/explanation/model.md). Format (YAML, version 1)::
#:
#:     format: sma_wrist/heat_balance
#:     version: 1
#:     form: peltier                # Eqs. P.1-P.3 (core.thermal.peltier)
#:     coupling_per_s: 0.0          # optional: muscle-muscle conductance over the muscle node's capacity [1/s]
#:     latent_C: [0.0, 0.0]         # optional: the wires' latent heat per layer (Eq. P.4) [degC per transformation]
#:     layers:                      # TEM 1 (muscle 1), TEM 2 (muscle 2): peltier.LAYER_KEYS each
#:       - {seebeck_V_per_K: 0.05, resistance_ohm: 2.0, conductance_W_per_K: 0.6, ...}
#:       - {...}
#:     identification: {...}       # provenance and held-out errors; informative only
HEAT_BALANCE_FORMAT = 'sma_wrist/heat_balance'
HEAT_BALANCE_FORMS = ('peltier',)
_HB_KEYS = {'format', 'version', 'form', 'coupling_per_s', 'latent_C', 'layers', 'identification'}


def heat_balance_file_dict(params: Any, identification: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The heat-balance file's content for a peltier.PeltierParams."""
    from sma_wrist.core.thermal import peltier as pe

    return {
        'format': HEAT_BALANCE_FORMAT,
        'version': VERSION,
        'form': 'peltier',
        'coupling_per_s': float(params.coupling_per_s),
        'latent_C': [float(x) for x in params.latent_C],
        'layers': [{k: float(getattr(layer, k)) for k in pe.LAYER_KEYS} for layer in params.layers],
        'identification': dict(identification or {}),
    }


def write_heat_balance_file(
    path: str | Path, params: Any, identification: Mapping[str, Any] | None = None, header: str = ''
) -> Path:
    """Write a peltier.PeltierParams as a version-1 heat-balance file (YAML) with an optional comment header."""
    return write_yaml_file(path, heat_balance_file_dict(params, identification), header)


def load_heat_balance_file(path: str | Path) -> Any:
    """The peltier.PeltierParams of a heat-balance file. Raises ParameterError naming the file and what is wrong
    (missing, not YAML, wrong format/version/form, a missing, unknown or non-finite key, a non-physical value)."""
    import yaml

    from sma_wrist.core.thermal import peltier as pe

    p = Path(path)
    how = 'sma-wrist commission writes one where the Peltier form predicts better'
    try:
        data = yaml.safe_load(p.read_text(encoding='utf-8'))
    except OSError as e:
        raise ParameterError(f'{p}: cannot read the heat-balance file ({e.strerror or e}); {how}') from None
    except UnicodeDecodeError as e:
        raise ParameterError(f'{p}: not a UTF-8 text heat-balance file (byte {e.start}: {e.reason})') from None
    except yaml.YAMLError as e:
        raise ParameterError(f'{p}: not a YAML heat-balance file ({str(e).splitlines()[0]})') from None
    if not isinstance(data, dict) or data.get('format') != HEAT_BALANCE_FORMAT:
        hint = " (a thermal file is thermal_file's)" if isinstance(data, dict) and data.get('format') == FORMAT else ''
        raise ParameterError(
            f'{p}: not a heat-balance file (need `format: {HEAT_BALANCE_FORMAT}` at the top level){hint}'
        )
    if data.get('version') != VERSION:
        raise ParameterError(
            f'{p}: heat-balance file version {data.get("version")!r} is not supported (need {VERSION})'
        )
    unknown = sorted(set(data) - _HB_KEYS)
    if unknown:
        raise ParameterError(
            f'{p}: unknown key(s) {", ".join(map(str, unknown))}; known: {", ".join(sorted(_HB_KEYS))}'
        )
    if data.get('form') not in HEAT_BALANCE_FORMS:
        raise ParameterError(f'{p}: form {data.get("form")!r} is not one of {", ".join(HEAT_BALANCE_FORMS)}')
    layers = data.get('layers')
    if not (isinstance(layers, list) and len(layers) == 2):
        raise ParameterError(f'{p}: layers must be a list of two (TEM 1, TEM 2)')
    out = []
    for i, row in enumerate(layers):
        if not isinstance(row, dict) or set(row) != set(pe.LAYER_KEYS):
            raise ParameterError(f'{p}: layers[{i}] must map exactly {", ".join(pe.LAYER_KEYS)} to numbers')
        try:
            out.append(pe.PeltierLayer(**{k: _number(p, f'layers[{i}].{k}', row[k]) for k in pe.LAYER_KEYS}))
        except ParameterError as e:
            raise ParameterError(f'{p}: layers[{i}]: {e}') from None
    coupling = _number(p, 'coupling_per_s', data.get('coupling_per_s', 0.0))
    latent = data.get('latent_C', [0.0, 0.0])
    if not (isinstance(latent, list) and len(latent) == 2):
        raise ParameterError(f'{p}: latent_C must be a list of two numbers (TEM 1, TEM 2) [degC], got {latent!r}')
    latent = [_number(p, f'latent_C[{i}]', x) for i, x in enumerate(latent)]
    try:
        return pe.PeltierParams(layers=(out[0], out[1]), coupling_per_s=coupling, latent_C=(latent[0], latent[1]))
    except ParameterError as e:
        raise ParameterError(f'{p}: {e}') from None
