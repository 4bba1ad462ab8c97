"""Where the commands write, checked before their work (a fit, a diagnosis), not after it.

An output path that is one of the command's inputs (a measured table, a bag's metadata.yaml) was
overwritten; a folder given as a file, or a file as a folder, failed with a traceback once the work
was done. These checks name the option and the path instead.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from sma_wrist.core.errors import SmaWristError


def _under_a_file(path: Path) -> Path | None:
    """The first ancestor of ``path`` that is a file (so nothing can be created there), or None."""
    for parent in path.absolute().parents:
        if parent.exists():
            return parent if not parent.is_dir() else None
    return None


def _input_hit(path: Path, inputs: Iterable[str | Path]) -> Path | None:
    """The input that ``path`` is, or is inside of (a bag folder), or None."""
    target = path.resolve()
    for inp in inputs:
        p = Path(inp).resolve()
        if target == p or (p.is_dir() and p in target.parents):
            return Path(inp)
    return None


def _check(
    path: str | Path | None,
    flag: str,
    inputs: Iterable[str | Path],
    error: type[SmaWristError],
    folder: bool,
    example: str | None = None,
) -> None:
    if not path:
        return
    p = Path(path)
    if folder and p.exists() and not p.is_dir():
        raise error(f'{flag} {p} is a file; give a folder for the report and the params file')
    if not folder and p.is_dir():
        raise error(f'{flag} {p} is a folder; give a file name' + (f', e.g. {p / example}' if example else ''))
    blocked = _under_a_file(p)
    if blocked is not None:
        raise error(f'{flag} {p}: {blocked} is a file, not a folder')
    hit = _input_hit(p, inputs)
    if hit is not None:
        raise error(
            f'{flag} {p} is {"inside " if hit.resolve() != p.resolve() else ""}the input {hit}: '
            f'it would be overwritten; give another {"folder" if folder else "path"}'
        )


def check_output_file(
    path: str | Path | None,
    flag: str,
    inputs: Iterable[str | Path] = (),
    error: type[SmaWristError] = SmaWristError,
    example: str | None = None,
) -> None:
    """``error`` if the file ``path`` cannot be written without harm: it is a folder (the message suggests
    ``example`` inside it), it would be created under a file, or it is (or is inside) one of ``inputs``."""
    _check(path, flag, inputs, error, folder=False, example=example)


def check_output_folder(
    path: str | Path | None,
    flag: str = '--out',
    inputs: Iterable[str | Path] = (),
    error: type[SmaWristError] = SmaWristError,
) -> None:
    """``error`` if the folder ``path`` cannot be used: it is a file, would be created under a file, or is (or is
    inside) one of ``inputs``."""
    _check(path, flag, inputs, error, folder=True)


#: where ``sma-wrist bench`` writes its figures unless ``--out`` or ``$SMA_WRIST_BENCH_DIR`` says otherwise
BENCH_DIR = 'runs/bench'
BENCH_OUT_HELP = f"folder for the sections' figures (default $SMA_WRIST_BENCH_DIR, else {BENCH_DIR})"


def bench_png(name: str) -> str:
    """Path of a benchmark's figure: in ``$SMA_WRIST_BENCH_DIR`` (``sma-wrist bench --out`` sets it; default
    :data:`BENCH_DIR`, next to the other commands' ``runs/`` folders, not the current folder), created if
    missing, so a run does not end in a traceback after minutes of work."""
    import os

    folder = Path(os.environ.get('SMA_WRIST_BENCH_DIR') or BENCH_DIR)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise SmaWristError(f'SMA_WRIST_BENCH_DIR={folder}: cannot hold the figures ({e.strerror or e})') from None
    return str(folder / name)


__all__ = ['BENCH_DIR', 'BENCH_OUT_HELP', 'check_output_file', 'check_output_folder', 'bench_png']
