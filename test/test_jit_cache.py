"""numba's on-disk cache follows edits to a kernel's helpers in other files (core/jit.py).

numba keys a cached kernel on its own file only (numba documents it): a caller in an unchanged file
keeps the old machine code of a helper it inlined from an edited one. The package drops its caches
when the sources of its kernel folders change; these tests run real numba on a two-file package.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from sma_wrist.core import jit

ROOT = Path(jit.__file__).resolve().parent.parent


def test_every_compiled_kernel_lives_in_a_folder_the_stamp_covers():
    users = {f.relative_to(ROOT).parts[0] for f in ROOT.rglob('*.py') if '_jit' in f.read_text()}
    assert users - {'core'}, 'the scan found no kernels outside core/: it is not looking'
    assert users <= set(jit.KERNEL_FOLDERS), f'kernels in {sorted(users - set(jit.KERNEL_FOLDERS))} are not stamped'


def test_a_source_edit_drops_the_caches_and_an_unchanged_tree_keeps_them(tmp_path):
    kern = tmp_path / 'core'
    (kern / '__pycache__').mkdir(parents=True)
    (kern / 'k.py').write_text('X = 1\n')
    other = tmp_path / 'cli.py'
    other.write_text('Y = 1\n')
    cached = [kern / '__pycache__' / 'k.f-1.py311.nbi', kern / '__pycache__' / 'k.f-1.py311.0.nbc']

    def write_caches():
        for f in cached:
            f.write_bytes(b'compiled')

    write_caches()
    assert jit.drop_stale_caches(tmp_path, ('core',))  # no stamp yet: caches of unknown sources go
    assert not any(f.exists() for f in cached)
    write_caches()
    assert not jit.drop_stale_caches(tmp_path, ('core',))
    other.write_text('Y = 2\n')  # outside the kernel folders
    assert not jit.drop_stale_caches(tmp_path, ('core',))
    assert all(f.exists() for f in cached)
    (kern / 'k.py').write_text('X = 2\n')
    assert jit.drop_stale_caches(tmp_path, ('core',))
    assert not any(f.exists() for f in cached)


RUN = textwrap.dedent("""
    import sys
    from pathlib import Path
    sys.path.insert(0, sys.argv[1])
    pkg = Path(sys.argv[1]) / 'pkg'
    if sys.argv[2] == 'locator':
        from sma_wrist.core.jit import install_cache_locator
        assert install_cache_locator(pkg, ('.',), Path(sys.argv[1]) / 'cache')
    elif sys.argv[2] == 'in-tree guard':
        from sma_wrist.core.jit import drop_stale_caches
        drop_stale_caches(pkg, ('.',))
    from pkg.caller import twice
    print(twice(1.0))
""")


def test_a_kernel_inlining_an_edited_helper_from_another_file_is_recompiled(tmp_path):
    """numba alone keeps the caller's stale copy of the helper (2.0 after the edit to 3.0); the
    package's locator and the in-tree fallback both recompile, and the locator writes nothing into
    the source tree (where pip would leave it behind on uninstall)."""
    pytest.importorskip('numba')
    pkg = tmp_path / 'pkg'
    pkg.mkdir()
    (pkg / '__init__.py').write_text('')
    (pkg / 'helper.py').write_text(
        'import numba\n\n@numba.njit(cache=True, inline="always")\ndef gain(x):\n    return 2.0 * x\n'
    )
    (pkg / 'caller.py').write_text(
        'import numba\nfrom pkg.helper import gain\n\n@numba.njit(cache=True)\ndef twice(x):\n    return gain(x)\n'
    )

    def run(mode):
        # numba's own default (next to the sources), whatever cache folder the user has set
        env = {k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'}
        out = subprocess.run(
            [sys.executable, '-c', RUN, str(tmp_path), mode], capture_output=True, text=True, env=env, timeout=120
        )
        assert out.returncode == 0, out.stderr
        return float(out.stdout.split()[-1])

    def in_tree():
        return sorted(f.name for f in pkg.rglob('*.nb[ic]'))

    assert run('locator') == 2.0  # compiles and caches
    assert in_tree() == [] and list((tmp_path / 'cache').rglob('*.nbi'))
    assert run('numba alone') == 2.0
    assert in_tree()
    (pkg / 'helper.py').write_text(
        'import numba\n\n@numba.njit(cache=True, inline="always")\ndef gain(x):\n    return 3.0 * x\n'
    )
    assert run('numba alone') == 2.0  # numba alone: the cached caller is stale
    assert run('locator') == 3.0
    assert run('in-tree guard') == 3.0


def test_the_package_caches_its_kernels_outside_its_own_folder(tmp_path):
    pytest.importorskip('numba')
    cache = tmp_path / 'cache'
    code = (
        'from sma_wrist.core.plant.kernel import step_many; from numba.core import caching;'
        'loc = (getattr(caching, "CacheImpl", None) or caching._CacheImpl)._locator_classes[0];'
        'print(loc.from_function(step_many.py_func, step_many.py_func.__code__.co_filename).get_cache_path())'
    )
    env = {**os.environ, 'NUMBA_CACHE_DIR': str(cache)}
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr
    assert Path(out.stdout.split()[-1]).parent == cache


def test_cache_folders_of_copies_that_are_gone_are_pruned_and_no_others(tmp_path):
    """Every clone, venv or reinstall of the package got its own cache sub-folder (~0.5 MB) that nothing removed."""
    cache, live = tmp_path / 'cache', tmp_path / 'clone' / 'core'
    live.mkdir(parents=True)
    for name, source in (('live', live), ('gone', tmp_path / 'deleted_clone' / 'core'), ('foreign', None)):
        (cache / name).mkdir(parents=True)
        (cache / name / 'k.f-1.py311.nbi').write_bytes(b'compiled')
        if source is not None:
            jit.mark_cache_folder(cache / name, source)
    assert jit.prune_caches(cache) == [cache / 'gone']
    assert sorted(d.name for d in cache.iterdir() if d.is_dir()) == ['foreign', 'live']  # unmarked: not ours
    jit.mark_cache_folder(cache / 'late', tmp_path / 'also_deleted')
    assert jit.prune_caches(cache) == []  # at most once an hour
    assert jit.prune_caches(cache, force=True) == [cache / 'late']


def test_the_package_marks_the_cache_folders_it_uses(tmp_path):
    pytest.importorskip('numba')
    cache = tmp_path / 'cache'
    code = 'import sma_wrist.core.plant.kernel'
    out = subprocess.run(
        [sys.executable, '-c', code],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, 'NUMBA_CACHE_DIR': str(cache)},
    )
    assert out.returncode == 0, out.stderr
    marks = {Path((d / jit.SOURCE_MARKER).read_text()) for d in cache.iterdir() if (d / jit.SOURCE_MARKER).is_file()}
    assert ROOT / 'core' / 'plant' in marks and all(m.is_dir() for m in marks)
