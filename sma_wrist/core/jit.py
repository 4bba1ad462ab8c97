"""The project's one optional-numba switch: :data:`AVAILABLE` and the ``_jit`` decorator.

Every compiled kernel under ``core/`` (``*/kernel.py``, ``*_kernel.py``) is plain Python compiled by
numba when it is installed (``pip install sma_wrist[fast]``); without numba the decorator returns the
function unchanged, with ``py_func`` pointing at itself, so the same code runs as the reference loop.
"""
from __future__ import annotations

try:  # numba is optional: a 20-100x faster per-sample plant, same numbers
    import numba as _numba

    AVAILABLE = True
    _jit = _numba.njit(cache=True, nogil=True)
except ImportError:  # pragma: no cover - exercised where numba is absent
    AVAILABLE = False

    def _jit(f):  # type: ignore[no-untyped-def]
        f.py_func = f
        return f
