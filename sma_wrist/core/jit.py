"""The project's one optional-numba switch: ``AVAILABLE`` and the ``_jit`` decorator.

Every compiled kernel under ``core/`` (``*/kernel.py``, ``*_kernel.py``) is plain Python compiled by
numba when it is installed (``pip install sma_wrist[fast]``); without numba the decorator returns the
function unchanged, with ``py_func`` pointing at itself, so the same code runs as the reference loop.

``_jit_inline`` is ``_jit`` for the small helpers the kernels call once per wire and step (the
load solve's elongation, the RK4 stage, the joint step): numba inlines them into their caller's IR.
A compiled call with array arguments costs ~50 ns (arguments unpacked, reference counts); the
elongation's arithmetic is ~75 ns. Same operations, same numbers (test_plant_kernel).

Where the compiled kernels are cached, and when they are stale:

- numba's on-disk cache (``cache=True``) checks only the source file of the function it compiled
  (numba documents it: "old function code might be used in the calculations"): a kernel
  that calls or inlines a helper from another file, or reads a constant from one, keeps its old
  machine code after that file changes in a source checkout or editable install.
- numba writes its cache next to the source (``__pycache__/*.nbi``, ``*.nbc``). pip does not know
  those files, so ``pip uninstall`` leaves the package folder behind with only them in it; Python
  then imports that folder as a namespace package ahead of a later editable install's finder
  (``import sma_wrist`` gives ``__file__ None`` and the CLI runs the old copy).

``PackageCacheLocator`` answers both: the package's kernels are cached in the user's cache
folder (``$XDG_CACHE_HOME/sma_wrist/numba``, ``NUMBA_CACHE_DIR`` when the user set it), one
sub-folder per installed copy, and stamped with the digest of every source in the folders that
hold kernels (:data:`KERNEL_FOLDERS`), so numba itself recompiles after an edit anywhere there.
Each sub-folder it writes names its source folder (:data:`SOURCE_MARKER`); :func:`prune_caches`
deletes the sub-folders whose copy is gone (an uninstalled package, a deleted clone or venv: ~0.5 MB
each, which otherwise pile up), at most once an hour, and never a folder it did not mark.
The locator plugs into numba's cache-locator list, which is not a public API; a numba without it
gets the older guard, :func:`drop_stale_caches`, on numba's in-tree cache.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

#: the in-tree cache stamp of :func:`drop_stale_caches`: the digest of the sources its caches were
#: written from
STAMP_NAME = 'numba-sources.sha256'
#: the package folders whose code the kernels compile or read constants from (an edit elsewhere,
#: e.g. the CLI or the nodes, keeps the compiled kernels)
KERNEL_FOLDERS = ('core', 'plants', 'sweep', 'diagnose', 'data', 'monitor')
PACKAGE_ROOT = Path(__file__).resolve().parent.parent
#: written into each cache sub-folder the package's locator uses: the source folder it caches
SOURCE_MARKER = 'sma_wrist-source.txt'
#: the cache folder's stamp of the last :func:`prune_caches`, and how often it runs [s]
PRUNE_STAMP, PRUNE_EVERY_S = '.sma_wrist-pruned', 3600.0


def kernel_array(x: Any, dtype: Any = float) -> np.ndarray:
    """``x`` as a C-ordered, writeable array of ``dtype``, copied only where it is not one already. numba compiles a
    kernel once per argument type, and a read-only array (a parameter's cached array, a broadcast view, an array
    that is writeable only once unpickled in a sweep's worker) is another type than a writeable one: passed both,
    a kernel was compiled twice (10-24 s of CPU each on a cold cache)."""
    return np.require(x, dtype, ['C_CONTIGUOUS', 'WRITEABLE'])


def source_digest(root: Path, folders: tuple[str, ...] = KERNEL_FOLDERS) -> str:
    """SHA-256 over the path and bytes of every ``*.py`` in ``folders`` of ``root`` (~3 ms here)."""
    h = hashlib.sha256()
    for f in sorted(g for d in folders for g in (root / d).rglob('*.py')):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def user_cache_dir() -> Path:
    """Where the package's compiled kernels go: ``NUMBA_CACHE_DIR`` if the user set one (numba's own
    switch), else ``$XDG_CACHE_HOME/sma_wrist/numba`` (``~/.cache/sma_wrist/numba``)."""
    if os.environ.get('NUMBA_CACHE_DIR'):
        return Path(os.environ['NUMBA_CACHE_DIR'])
    return Path(os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache') / 'sma_wrist' / 'numba'


def drop_stale_caches(root: Path, folders: tuple[str, ...] = KERNEL_FOLDERS) -> bool:
    """Delete numba's in-tree cache files (``__pycache__/*.nbi``, ``*.nbc``) under ``root`` when a
    source in ``folders`` changed since they were written; True if it deleted. The fallback for a numba
    without a cache-locator list (:func:`install_cache_locator`). A tree numba cannot write is left
    alone: numba then caches in the user's cache folder, where a new install gets a new stamp anyway."""
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


def mark_cache_folder(cache_path: str | Path, source_folder: str | Path) -> None:
    """Write :data:`SOURCE_MARKER` (the source folder's path) into a cache sub-folder, once."""
    marker = Path(cache_path) / SOURCE_MARKER
    try:
        if not marker.is_file():
            marker.parent.mkdir(parents=True, exist_ok=True)
            marker.write_text(str(source_folder))
    except OSError:  # a read-only cache folder: numba then does not cache there either
        pass


def prune_caches(cache_dir: Path, *, force: bool = False) -> list[Path]:
    """Delete the sub-folders of ``cache_dir`` whose :data:`SOURCE_MARKER` names a source folder that no
    longer exists; the deleted ones. Unmarked folders (other packages' under a shared ``NUMBA_CACHE_DIR``,
    or written before the marker existed) are left alone. Runs at most every :data:`PRUNE_EVERY_S`
    unless ``force``; a race with another process pruning or compiling only skips a folder."""
    import shutil
    import time

    stamp = cache_dir / PRUNE_STAMP
    try:
        if not force and time.time() - stamp.stat().st_mtime < PRUNE_EVERY_S:
            return []
    except OSError:
        pass  # never pruned (or no cache folder yet)
    gone: list[Path] = []
    try:
        subs = [d for d in cache_dir.iterdir() if d.is_dir()]
        for d in subs:
            try:
                source = (d / SOURCE_MARKER).read_text().strip()
            except OSError:
                continue
            if source and not Path(source).is_dir():
                shutil.rmtree(d, ignore_errors=True)
                gone.append(d)
        stamp.touch()
    except OSError:
        pass
    return gone


def install_cache_locator(root: Path, folders: tuple[str, ...] = KERNEL_FOLDERS, cache_dir: Path | None = None) -> bool:
    """Cache every kernel compiled from a file under ``root`` in ``cache_dir`` (default
    :func:`user_cache_dir`), stamped with :func:`source_digest` of ``folders``; other packages' kernels
    keep numba's locators. False (nothing installed) if this numba has no locator list to extend."""
    try:
        from numba.core import caching

        impl = getattr(caching, 'CacheImpl', None) or caching._CacheImpl  # renamed in numba 0.59
        base = (caching._SourceFileBackedLocatorMixin, caching._CacheLocator)
    except (ImportError, AttributeError):
        return False
    root = root.resolve()
    digest = functools.cache(lambda: source_digest(root, folders))  # once per process, at first compile
    marked: set[str] = set()  # cache sub-folders marked by this process
    pruned: list[list[Path]] = []  # prune_caches' answer, once per process, at the first kernel

    class PackageCacheLocator(*base):  # type: ignore[misc]
        def __init__(self, py_func, py_file):  # type: ignore[no-untyped-def]
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            where = cache_dir if cache_dir is not None else user_cache_dir()
            self._cache_path = os.path.join(where, self.get_suitable_cache_subpath(py_file))
            if self._cache_path not in marked:
                marked.add(self._cache_path)
                mark_cache_folder(self._cache_path, Path(py_file).resolve().parent)
                if not pruned:
                    pruned.append(prune_caches(Path(where)))

        def get_cache_path(self) -> str:
            return self._cache_path

        def get_source_stamp(self):  # type: ignore[no-untyped-def]
            # numba's stamp is the file's mtime and size; any kernel-folder source counts here
            return (digest(), super().get_source_stamp())

        @classmethod
        def from_function(cls, py_func, py_file):  # type: ignore[no-untyped-def]
            try:
                if not Path(py_file).resolve().is_relative_to(root):
                    return None
            except (OSError, ValueError):
                return None
            return super().from_function(py_func, py_file)  # None if the folder cannot be written

    impl._locator_classes = [c for c in impl._locator_classes if getattr(c, '_sma_wrist_root', None) != root]
    PackageCacheLocator._sma_wrist_root = root
    impl._locator_classes.insert(0, PackageCacheLocator)
    return True


try:  # numba is optional: a 20-100x faster per-sample plant, same numbers
    import numba as _numba

    AVAILABLE = True
    if not install_cache_locator(PACKAGE_ROOT):
        drop_stale_caches(PACKAGE_ROOT)
    _jit = _numba.njit(cache=True, nogil=True)
    _jit_inline = _numba.njit(cache=True, nogil=True, inline='always')
except ImportError:  # pragma: no cover - exercised where numba is absent
    AVAILABLE = False

    def _jit(f):  # type: ignore[no-untyped-def]
        f.py_func = f
        return f

    _jit_inline = _jit
