"""The identified-wire file ``hysteresis.yaml``: one SD-GPI parameter set, versioned.

Written by ``sma-wrist identify hysteresis``; read by plant_sim, hysteresis_compensator and
``sma-wrist diagnose`` through their ``hysteresis_file`` parameter (empty: the default set of
:mod:`sma_wrist.core.hysteresis.default_params`). Format version 1::

    format: sma_wrist.hysteresis      # fixed
    version: 1
    name: <free text>
    units: {temperature: degC, load: kgf per 0.25 mm wire, elongation: mm of an 80 mm wire}
    model:                            # Eqs. 3.19-3.24, 4.1-4.6, see core/hysteresis/sdgpi.py
      n: 15                           # play operators
      p0: 1.0                         # memoryless weight, Eq. 4.1
      k_f_mm: 6.0                     # mirror constant, Eq. 4.2
      rho: ..., tau_per_mm: ..., c_thr_mm: ...    # density and thresholds, Eqs. 3.23-3.24
      c: [c0, c1, c2, c3]             # memoryless set while heating, Eq. 3.22
      d: [d0, d1, d2, d3]             # while cooling
      load_edges_kgf: [m0, ..., mK]   # K load sections
      a: K x 4 x 3                    # a_i(m) = s0 m^2 + s1 m + s2 per section, Eqs. 4.4-4.5
      b: K x 4 x 3
      T_valid_C: [lo, hi]             # temperatures the model is trusted at
    identification: {...}             # informational: data files, stresses, fit errors

Unknown keys are ignored; a missing or malformed one raises ParameterError naming the file
and the key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.sdgpi import EnvelopeSections, SDGPIParams
from sma_wrist.core.yaml_file import write_yaml_file

FORMAT = 'sma_wrist.hysteresis'
VERSION = 1
UNITS = {'temperature': 'degC', 'load': 'kgf per 0.25 mm wire', 'elongation': 'mm of an 80 mm wire'}

#: the most play operators a file may ask for: the seed finds little gain beyond 15 (Sec. 4.1.1), and each one
#: is work in every plant step
MAX_OPERATORS = 100


def params_to_dict(params: SDGPIParams, identification: dict[str, Any] | None = None) -> dict[str, Any]:
    """The YAML document (plain lists and floats) of a parameter set."""
    env = params.envelopes
    model = {
        'n': int(params.n),
        'p0': float(params.p0),
        'k_f_mm': float(params.k_f),
        'rho': float(params.rho),
        'tau_per_mm': float(params.tau),
        'c_thr_mm': float(params.c_thr),
        'c': [float(v) for v in params.c],
        'd': [float(v) for v in params.d],
        'load_edges_kgf': [float(v) for v in env.edges_kg],
        'a': np.asarray(env.a, dtype=float).tolist(),
        'b': np.asarray(env.b, dtype=float).tolist(),
        'T_valid_C': [float(params.T_valid[0]), float(params.T_valid[1])],
    }
    doc: dict[str, Any] = {
        'format': FORMAT,
        'version': VERSION,
        'name': params.name,
        'units': dict(UNITS),
        'model': model,
    }
    if identification:
        doc['identification'] = identification
    return doc


def save_hysteresis(path: str | Path, params: SDGPIParams, identification: dict[str, Any] | None = None) -> Path:
    """Write ``hysteresis.yaml`` (format version 1)."""
    return write_yaml_file(
        path,
        params_to_dict(params, identification),
        'SD-GPI hysteresis of one wire (sma_wrist hysteresis file, format version 1; '
        'see sma_wrist/core/hysteresis/params_file.py)',
    )


def params_from_dict(doc: Any, where: str = 'hysteresis file') -> SDGPIParams:
    """Validate a parsed document and build the parameter set."""
    if not isinstance(doc, dict) or doc.get('format') != FORMAT:
        raise ParameterError(f'{where}: not a sma_wrist hysteresis file (needs "format: {FORMAT}")')
    if doc.get('version') != VERSION:
        raise ParameterError(
            f'{where}: format version {doc.get("version")!r} is not supported (this sma_wrist reads {VERSION})'
        )
    m = doc.get('model')
    if not isinstance(m, dict):
        raise ParameterError(f'{where}: the "model" section is missing')

    def num(key: str) -> float:
        try:
            v = float(m[key])
        except (KeyError, TypeError, ValueError):
            raise ParameterError(f'{where}: model.{key} must be a number') from None
        if not np.isfinite(v):
            raise ParameterError(f'{where}: model.{key} must be finite, got {v}')
        return v

    def arr(key: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
        try:
            v = np.asarray(m[key], dtype=float)
        except (KeyError, TypeError, ValueError):
            raise ParameterError(f'{where}: model.{key} must be a list of numbers') from None
        if shape is not None and v.shape != shape:
            raise ParameterError(f'{where}: model.{key} must have shape {shape}, got {v.shape}')
        if not np.all(np.isfinite(v)):
            raise ParameterError(f'{where}: model.{key} has non-finite entries')
        return v

    edges = arr('load_edges_kgf')
    k = edges.size - 1
    if edges.ndim != 1 or k < 1:
        raise ParameterError(f'{where}: model.load_edges_kgf needs >= 2 increasing loads')
    env = EnvelopeSections(edges, arr('a', (k, 4, 3)), arr('b', (k, 4, 3)))
    T_valid = arr('T_valid_C', (2,))
    if not T_valid[0] < T_valid[1]:
        raise ParameterError(f'{where}: model.T_valid_C must be [low, high] with low < high')
    n_raw = num('n')
    if n_raw != int(n_raw) or not 1 <= n_raw <= MAX_OPERATORS:  # n: 1e8 ran for minutes at 4 GB; 15.5 was cut to 15
        raise ParameterError(
            f'{where}: model.n = {n_raw:g} must be a whole number of play operators in '
            f'[1, {MAX_OPERATORS}] (the seed uses 15, Sec. 4.1.1)'
        )
    n = int(n_raw)
    return SDGPIParams(
        env,
        arr('c', (4,)),
        arr('d', (4,)),
        num('rho'),
        num('tau_per_mm'),
        num('c_thr_mm'),
        n=n,
        p0=num('p0'),
        k_f=num('k_f_mm'),
        T_valid=(float(T_valid[0]), float(T_valid[1])),
        name=str(doc.get('name', Path(where).stem)),
    )


def load_hysteresis(path: str | Path) -> SDGPIParams:
    """Read and validate ``hysteresis.yaml``; ParameterError names the file and what is wrong."""
    import yaml

    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text(encoding='utf-8'))
    except OSError as e:
        raise ParameterError(f'hysteresis_file {p}: cannot read it ({e.strerror or e})') from None
    except UnicodeDecodeError as e:  # a binary file given by mistake (a bag, a .mat)
        raise ParameterError(
            f'hysteresis_file {p}: not a UTF-8 text file (byte {e.start}: {e.reason}); '
            'write one with `sma-wrist identify hysteresis ... --out DIR`'
        ) from None
    except yaml.YAMLError as e:
        raise ParameterError(f'hysteresis_file {p}: not valid YAML ({str(e).splitlines()[0]})') from None
    return params_from_dict(doc, str(p))


def hysteresis_params(path: str | Path | None = None) -> SDGPIParams:
    """The SD-GPI set the nodes use: ``path`` if given and non-empty, else the default set."""
    if path:
        return load_hysteresis(path)
    from sma_wrist.core.hysteresis.default_params import default_sdgpi

    return default_sdgpi()
