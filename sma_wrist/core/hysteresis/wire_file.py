"""The model's wire file ``wire.yaml``: a wire family other than the SD-GPI, versioned.

Written by ``sma-wrist commission`` where a phase-fraction wire predicts the wrist's held-out angle better than every
SD-GPI candidate; read by plant_sim, ``sma-wrist diagnose`` and the twin monitor through the ``wire_file`` parameter
(empty: the SD-GPI of ``hysteresis_file``). The compensator keeps inverting the SD-GPI of ``hysteresis_file``: this
file is the model's wire, not the inverse's. Format version 1::

    format: sma_wrist.wire            # fixed
    version: 1
    form: phase_fraction              # the family (sma_wrist/core/hysteresis/phase_fraction.py)
    law: linear                       # its constitutive details: linear (Eq. 4: linear detwinning ramp, Reuss
                                      # compliance) or brinson (Eq. 4b: Brinson 1993's cosine ramp, Voigt modulus);
                                      # absent: linear (the files written before the choice existed)
    name: <free text>
    model:                            # PhaseFractionWire's fields: temperatures [degC] at sigma_ref_MPa, slopes
      M_f_C: ...                      # [MPa/degC], moduli [GPa], stresses [MPa], strain [1], offset_mm [mm]
      T_valid_C: [lo, hi]
    identification: {...}             # informational

A missing or malformed key raises ParameterError naming the file and the key; unknown keys are refused (a typo
would otherwise leave a value at its default).
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any

from sma_wrist.core.errors import ParameterError
from sma_wrist.core.hysteresis.phase_fraction import LAWS, PhaseFractionWire
from sma_wrist.core.yaml_file import write_yaml_file

FORMAT = 'sma_wrist.wire'
VERSION = 1
FORMS = ('phase_fraction',)


def wire_to_dict(wire: PhaseFractionWire, identification: dict[str, Any] | None = None) -> dict[str, Any]:
    """The YAML document of a phase-fraction wire."""
    model: dict[str, Any] = {k: round(v, 6) for k, v in wire.values().items()}
    model['T_valid_C'] = [float(v) for v in wire.T_valid]
    doc: dict[str, Any] = {'format': FORMAT, 'version': VERSION, 'form': 'phase_fraction', 'law': wire.law}
    doc['name'] = wire.name
    doc['model'] = model
    if identification:
        doc['identification'] = identification
    return doc


def save_wire_file(path: str | Path, wire: PhaseFractionWire, identification: dict[str, Any] | None = None) -> Path:
    """Write ``wire.yaml`` (format version 1)."""
    return write_yaml_file(
        path,
        wire_to_dict(wire, identification),
        "the model wrist's wire (sma-wrist commission); name it as wire_file of plant_sim",
    )


def wire_from_dict(doc: Any, where: str = 'wire file') -> PhaseFractionWire:
    """The wire of a ``wire.yaml`` document; ParameterError naming ``where`` and the key on anything malformed."""
    if not isinstance(doc, dict):
        raise ParameterError(f'{where}: not a mapping (expected format: {FORMAT})')
    if doc.get('format') != FORMAT:
        raise ParameterError(f'{where}: format must be {FORMAT!r}, got {doc.get("format")!r}')
    if doc.get('version') != VERSION:
        raise ParameterError(f'{where}: version {doc.get("version")!r} is not supported (this reader: {VERSION})')
    if doc.get('form') not in FORMS:
        raise ParameterError(f'{where}: form must be one of {", ".join(FORMS)}, got {doc.get("form")!r}')
    law = doc.get('law', 'linear')
    if law not in LAWS:
        raise ParameterError(f'{where}: law must be one of {", ".join(LAWS)}, got {law!r}')
    model = doc.get('model')
    if not isinstance(model, dict):
        raise ParameterError(f'{where}: model must be a mapping of the wire parameters')
    known = {f.name for f in fields(PhaseFractionWire)} - {'T_valid', 'name', 'law'}
    unknown = sorted(set(model) - known - {'T_valid_C'})
    if unknown:
        raise ParameterError(
            f'{where}: model has no parameter {", ".join(unknown)} (known: {", ".join(sorted(known))})'
        )
    kw: dict[str, Any] = {}
    for k, v in model.items():
        if k == 'T_valid_C':
            if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, (int, float)) for x in v)):
                raise ParameterError(f'{where}: model.T_valid_C must be [lo, hi] in degC, got {v!r}')
            kw['T_valid'] = (float(v[0]), float(v[1]))
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ParameterError(f'{where}: model.{k} must be a number, got {v!r}')
        else:
            kw[k] = float(v)
    try:
        return PhaseFractionWire(**kw, law=law, name=str(doc.get('name') or 'phase-fraction wire'))
    except ParameterError as e:
        raise ParameterError(f'{where}: {e}') from None


def load_wire_file(path: str | Path) -> PhaseFractionWire:
    """Read and validate ``wire.yaml``; ParameterError names the file and what is wrong."""
    import yaml

    p = Path(path)
    try:
        doc = yaml.safe_load(p.read_text(encoding='utf-8'))
    except OSError as e:
        raise ParameterError(f'wire file {p}: cannot be read ({e.strerror or e})') from None
    except yaml.YAMLError as e:
        raise ParameterError(f'wire file {p}: not YAML ({str(e).splitlines()[0]})') from None
    return wire_from_dict(doc, f'wire file {p}')


__all__ = ['save_wire_file', 'load_wire_file', 'wire_from_dict', 'wire_to_dict', 'FORMAT']
