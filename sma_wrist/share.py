"""Locate the package's data files (msg_defs/, config/, launch/) under every install layout.

Looked up, in order: the source tree (a checkout, or ``colcon build --symlink-install``),
``<sys.prefix>/share/sma_wrist`` (where ``pip install`` puts setup.py's data_files), and
every ``$AMENT_PREFIX_PATH/share/sma_wrist`` (a sourced ROS 2 workspace).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from sma_wrist.core.errors import SmaWristError

PACKAGE = 'sma_wrist'


class ShareFileNotFound(SmaWristError):
    """A data file of the package is not installed where expected."""


def candidates(relative: str) -> list[Path]:
    roots = [Path(__file__).resolve().parent.parent, Path(sys.prefix) / 'share' / PACKAGE]
    roots += [Path(p) / 'share' / PACKAGE for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return [r / relative for r in roots]


def share_path(relative: str) -> Path:
    """Path of a data file, e.g. ``share_path('config/wrist.yaml')``."""
    for p in candidates(relative):
        if p.exists():
            return p
    raise ShareFileNotFound(f'{relative} not found; looked in: ' + ', '.join(str(p) for p in candidates(relative)))
