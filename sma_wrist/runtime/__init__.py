"""Embedded single-process rclpy runtime for machines without ROS 2.

Usage::

    from sma_wrist import runtime
    runtime.activate()            # before importing node modules
    from sma_wrist.runtime.launch import run_nodes
    result = run_nodes([PlantSim, TemController], duration=10.0, bag='out/run1')

:func:`activate` installs a ``sys.meta_path`` finder so that ``import rclpy``,
``from std_msgs.msg import Float64`` etc. resolve to this package -- but only where the
real rclpy is not importable (or when forced before the real one is imported).  Node
modules never branch on the runtime; they import rclpy as usual.  See doc/explanation/runtime.md.
"""

from __future__ import annotations

import importlib.util
import sys
from typing import Any

from .errors import ActivationError

__all__ = ['activate', 'bench_messages', 'deactivate', 'using_embedded']

_finder: Any = None


def _real_rclpy_loaded() -> bool:
    mod = sys.modules.get('rclpy')
    return mod is not None and not getattr(mod, '__embedded__', False)


def _real_rclpy_importable() -> bool:
    if _real_rclpy_loaded():
        return True
    try:
        return importlib.util.find_spec('rclpy') is not None
    except (ImportError, ValueError):
        return False


def using_embedded() -> bool:
    """True if ``import rclpy`` gives (or will give) the embedded runtime."""
    return _finder is not None and _finder in sys.meta_path


def activate(force: bool = False) -> bool:
    """Install the embedded rclpy and message packages; return True if embedded is in use.

    Without ``force`` nothing is installed when a real rclpy is importable (ROS 2 is
    sourced) and False is returned.  With ``force`` the embedded runtime is installed even
    then, as long as the real rclpy has not been imported yet.  Raises ActivationError if
    the real rclpy is already imported and ``force`` is given.
    """
    global _finder
    if using_embedded():
        return True
    if _real_rclpy_loaded():
        if force:
            raise ActivationError(
                'cannot activate the embedded rclpy: the real rclpy '
                f'({getattr(sys.modules["rclpy"], "__file__", "?")}) is already imported in this '
                'process; call sma_wrist.runtime.activate(force=True) before anything imports rclpy'
            )
        return False
    if not force and _real_rclpy_importable():
        return False
    from .finder import EmbeddedFinder

    finder = EmbeddedFinder()
    stale = [m for m in sys.modules if finder.handles(m)]
    if stale:
        raise ActivationError(
            f'cannot activate the embedded runtime: modules {sorted(stale)[:5]} are already imported from elsewhere'
        )
    sys.meta_path.insert(0, finder)
    _finder = finder
    return True


def deactivate() -> None:
    """Remove the finder and the aliased modules (tests)."""
    global _finder
    if _finder is None:
        return
    if _finder in sys.meta_path:
        sys.meta_path.remove(_finder)
    for name in [m for m in sys.modules if _finder.handles(m)]:
        del sys.modules[name]
    _finder = None


def bench_messages(n: int = 20000, *, record: bool = False) -> dict[str, float]:
    """Measure publish->callback throughput of the embedded middleware (see bench.py)."""
    from .bench import bench_messages as _bench

    return _bench(n, record=record)
