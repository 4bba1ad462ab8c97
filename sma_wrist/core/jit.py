"""The project's one optional-numba switch: :data:`AVAILABLE` and the ``_jit`` decorator.

Every compiled kernel under ``core/`` (``*/kernel.py``, ``*_kernel.py``) is plain Python compiled by
numba when it is installed (``pip install sma_wrist[fast]``); without numba the decorator returns the
function unchanged, with ``py_func`` pointing at itself, so the same code runs as the reference loop.

``_jit_inline`` is ``_jit`` for the small helpers the kernels call once per wire and step (the
load solve's elongation, the RK4 stage, the joint step): numba inlines them into their caller's IR.
A compiled call with array arguments costs ~50 ns (arguments unpacked, reference counts); the
elongation's arithmetic is ~75 ns. Same operations, same numbers (test_plant_kernel).
"""
from __future__ import annotations

try:  # numba is optional: a 20-100x faster per-sample plant, same numbers
    import numba as _numba

    AVAILABLE = True
    _jit = _numba.njit(cache=True, nogil=True)
    _jit_inline = _numba.njit(cache=True, nogil=True, inline='always')
except ImportError:  # pragma: no cover - exercised where numba is absent
    AVAILABLE = False

    def _jit(f):  # type: ignore[no-untyped-def]
        f.py_func = f
        return f

    _jit_inline = _jit
