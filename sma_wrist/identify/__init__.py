"""Identification of the wrist's models from a user's measurements (``sma-wrist identify``).

Capability folder beside ``diagnose/``: reading and segmenting measurement files, the
before/after reports and the CLI; the numerical fits stay in :mod:`sma_wrist.core`.
Sub-commands are modules of this package listed in :data:`SUBCOMMANDS`; each defines
``register(subparsers)`` (adds its parser, with ``func`` set) and keeps its top-level imports
light, so building the CLI parser stays cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

#: modules of this package that add an ``identify`` sub-command (absent ones are skipped)
SUBCOMMANDS = ('hysteresis', 'thermal')


def add_parser(sub: Any) -> Any:
    """Add ``identify`` and its sub-commands to the top-level sub-parsers ``sub``."""
    p = sub.add_parser(
        'identify', help='identify the hysteresis or thermal model from measured data (doc/howto/identify_wire.md)'
    )
    isub = p.add_subparsers(dest='identify_command', required=True, metavar='WHAT')
    for name in SUBCOMMANDS:
        try:
            mod = importlib.import_module(f'{__name__}.{name}')
        except ModuleNotFoundError as e:
            if e.name == f'{__name__}.{name}':
                continue
            raise
        mod.register(isub)
    return p
