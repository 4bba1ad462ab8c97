"""The code follows ruff.toml: the linter finds nothing and the formatter would change nothing.

`ruff check .` and `ruff format --check .` from the repository root are the same checks; this test makes them part
of the suite, so CI runs them on every change."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _ruff() -> list[str]:
    exe = shutil.which('ruff')
    if exe:
        return [exe]
    pytest.importorskip('ruff', reason="ruff is in the 'test' extra: pip install '.[test]'")
    return [sys.executable, '-m', 'ruff']


@pytest.mark.parametrize('args', [('check',), ('format', '--check')], ids=['lint', 'format'])
def test_the_code_follows_ruff_toml(args: tuple[str, ...]) -> None:
    r = subprocess.run(
        [*_ruff(), *args, '--config', str(ROOT / 'ruff.toml'), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=ROOT,
    )
    assert r.returncode == 0, (
        f'ruff {" ".join(args)} (fix with: ruff check --fix . && ruff format .):\n{r.stdout}{r.stderr}'
    )
