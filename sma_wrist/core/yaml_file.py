"""The one writer of the YAML files the package hands its users: the model's files (a wire, a hysteresis set, a
thermal or heat-balance file) and the ROS 2 params files the diagnosis and commissioning write.

Every such file is a comment header (what wrote it, what it is for) and then the document in its own key order, so
that a person reading it finds the keys where the writer put them and a diff of two of them lines up."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any


def write_yaml_file(path: str | Path, doc: Mapping[str, Any], comment: str = '', flow_lists: bool = False) -> Path:
    """Write ``doc`` to ``path`` (its folder created) under ``comment``, one ``# `` line per line of it (an empty line
    a bare ``#``), and return the path.

    ``flow_lists``: lists of plain values on one line (``[1, 2]``, as a ROS 2 params file writes the wiring), else
    every value on its own line."""
    import yaml

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = ''.join(f'# {line}\n' if line else '#\n' for line in comment.splitlines())
    text += yaml.safe_dump(dict(doc), sort_keys=False, default_flow_style=None if flow_lists else False)
    p.write_text(text, encoding='utf-8')
    return p
