"""Typed errors raised by the numerical core.

Every error names the offending quantity, its value and the valid range, so a node
adapter can log it verbatim and a CLI user sees what to change.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np


class SmaWristError(Exception):
    """Base class of every error raised on purpose by sma_wrist."""


class ModelInputError(SmaWristError, ValueError):
    """An input to a model is non-finite or outside the model's validity envelope."""

    def __init__(self, name: str, value: object, valid: str, unit: str = '') -> None:
        self.name = name
        self.value = value
        self.valid = valid
        self.unit = unit
        u = f' {unit}' if unit else ''
        super().__init__(f'{name} = {value!r}{u} is outside the valid range {valid}{u}')


class ParameterError(SmaWristError, ValueError):
    """A model or controller parameter set is inconsistent or out of range."""


def check_finite(name: str, value: object, unit: str = '') -> None:
    """Raise ModelInputError if any element of value is NaN or infinite."""
    if type(value) is float and math.isfinite(value):
        return
    arr = np.asarray(value, dtype=float)
    if np.isfinite(arr).all():  # the method, not np.all(): this runs on every controller sample
        return
    bad = arr[~np.isfinite(arr)].ravel()[0] if arr.ndim else float(arr)
    raise ModelInputError(name, float(bad), '(finite numbers)', unit)


def check_range(name: str, value: object, lo: float, hi: float, unit: str = '') -> None:
    """Raise ModelInputError unless every element of value is finite and in [lo, hi]."""
    check_finite(name, value, unit)
    arr = np.asarray(value, dtype=float)
    if arr.size and (arr.min() < lo or arr.max() > hi):
        bad = arr.min() if arr.min() < lo else arr.max()
        raise ModelInputError(name, float(bad), f'[{lo:g}, {hi:g}]', unit)


def check_positive(name: str, value: float, unit: str = '') -> None:
    """Raise ModelInputError unless value is a finite number > 0."""
    if not (isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value > 0):
        raise ModelInputError(name, value, '(0, inf)', unit)


def format_choices(choices: Iterable[str]) -> str:
    return '{' + ', '.join(sorted(choices)) + '}'
