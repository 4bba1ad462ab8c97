"""The project's one optional-numba switch: :data:`AVAILABLE` and the ``_jit`` decorator.

Every compiled kernel under ``core/`` (``*/kernel.py``, ``*_kernel.py``) is plain Python compiled by
numba when it is installed (``pip install sma_wrist[fast]``); without numba the decorator returns the
function unchanged, with ``py_func`` pointing at itself, so the same code runs as the reference loop.

``_jit_inline`` is ``_jit`` for the small helpers the kernels call once per wire and step (the
load solve's elongation, the RK4 stage, the joint step): numba inlines them into their caller's IR.
A compiled call with array arguments costs ~50 ns (arguments unpacked, reference counts); the
elongation's arithmetic is ~75 ns. Same operations, same numbers (test_plant_kernel).

numba's on-disk cache (``cache=True``) checks only the source file of the function it compiled
(numba issue #1833, documented: "old function code might be used in the calculations"): a kernel
that calls or inlines a helper from another file, or reads a constant from one, keeps its old
machine code after that file changes in a source checkout or editable install.
:func:`drop_stale_caches` therefore keys the package's caches on the sources of every folder that
holds kernels (:data:`KERNEL_FOLDERS`) at import.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: the package's cache stamp: the digest of its sources when its numba caches were written
STAMP_NAME = 'numba-sources.sha256'
#: the package folders whose code the kernels compile or read constants from (an edit elsewhere,
#: e.g. the CLI or the nodes, keeps the compiled kernels)
KERNEL_FOLDERS = ('core', 'plants', 'sweep', 'diagnose', 'data')


def source_digest(root: Path, folders: tuple[str, ...] = KERNEL_FOLDERS) -> str:
    """SHA-256 over the path and bytes of every ``*.py`` in ``folders`` of ``root`` (~3 ms here)."""
    h = hashlib.sha256()
    for f in sorted(g for d in folders for g in (root / d).rglob('*.py')):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def drop_stale_caches(root: Path, folders: tuple[str, ...] = KERNEL_FOLDERS) -> bool:
    """Delete numba's in-tree cache files (``__pycache__/*.nbi``, ``*.nbc``) under ``root`` when a
    source in ``folders`` changed since they were written; True if it deleted. A tree numba cannot write
    (an install into a read-only prefix) is left alone: numba then caches in the user's cache
    folder, and a new install gives every file a new stamp there anyway."""
    stamp = root / '__pycache__' / STAMP_NAME
    try:
        digest = source_digest(root, folders)
        if stamp.is_file() and stamp.read_text() == digest:
            return False
        for f in [*root.rglob('__pycache__/*.nbi'), *root.rglob('__pycache__/*.nbc')]:
            f.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f'{STAMP_NAME}.{os.getpid()}')  # atomic: parallel imports (xdist, sweep workers)
        tmp.write_text(digest)
        os.replace(tmp, stamp)
        return True
    except OSError:
        return False


try:  # numba is optional: a 20-100x faster per-sample plant, same numbers
    import numba as _numba

    AVAILABLE = True
    drop_stale_caches(Path(__file__).resolve().parent.parent)
    _jit = _numba.njit(cache=True, nogil=True)
    _jit_inline = _numba.njit(cache=True, nogil=True, inline='always')
except ImportError:  # pragma: no cover - exercised where numba is absent
    AVAILABLE = False

    def _jit(f):  # type: ignore[no-untyped-def]
        f.py_func = f
        return f

    _jit_inline = _jit
