"""Shared test set-up: the embedded rclpy runtime (before anything imports rclpy) and a
probe node that publishes inputs and collects outputs of a node under test."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import pytest

from sma_wrist import runtime

runtime.activate()

try:  # the property tests guard results, not speed: hypothesis's 200 ms deadline per example failed them on a loaded
    # machine (DeadlineExceeded in the codec's round trip with ~10 processes per core); tests may still set their own
    from hypothesis import settings as _hypothesis

    _hypothesis.register_profile('sma_wrist', deadline=None)
    _hypothesis.load_profile('sma_wrist')
except ImportError:
    pass


def pytest_configure(config: pytest.Config) -> None:
    # registered here too, so the marks below are known when pytest-xdist is not installed
    config.addinivalue_line('markers', 'xdist_group(name): run these tests on one pytest-xdist worker')
    config.addinivalue_line(
        'markers',
        'exclusive: a wall-clock real-time test; under pytest-xdist the other '
        'workers wait while it runs, so it has the CPUs a serial run would give it',
    )
    _warm_kernels(config)


def package_env() -> dict[str, str]:
    """The environment for a child Python that imports ``sma_wrist``: this run's copy of the package first on its path
    (the installed one under .ci/run, which runs from test/; the checkout under ``python -m pytest test`` from the
    root). numba caches per source folder: a child that imported another copy would compile every kernel it meets
    again, on a fresh clone ~65 s of CPU for the monitor's command line alone. A child run in the checkout's root
    finds the checkout first whatever the path says: give it another working directory."""
    import sma_wrist

    here = str(Path(sma_wrist.__file__).resolve().parent.parent)
    return {**os.environ, 'PYTHONPATH': os.pathsep.join(p for p in (here, os.environ.get('PYTHONPATH')) if p)}


def _warm_kernels(config: pytest.Config) -> None:
    """Under ``pytest -n N``, in the controller before the workers start: compile the numba kernels once,
    the parts of warm_kernels.py side by side, so the workers load the cache instead of each compiling
    every kernel at the same time (a fresh clone's CI run: ~1 min of the suite's time on 2 cores). Three parts
    of 25-60 s of CPU each on a cold cache (measured on a loaded machine: closed_loops 58 s, replays 25 s,
    model_wires 26 s), side by side on 2 cores. Warm cache: a few seconds of imports. ``SMA_WRIST_NO_WARM=1`` skips it; a part that fails only leaves its
    kernels to the tests, as before."""
    import subprocess
    import sys
    import time

    from sma_wrist.core import jit

    if (
        hasattr(config, 'workerinput')
        or not getattr(config.option, 'numprocesses', None)
        or os.environ.get('SMA_WRIST_NO_WARM')
        or not jit.AVAILABLE
    ):
        return
    script = Path(__file__).with_name('warm_kernels.py')
    t0 = time.perf_counter()
    procs = [
        subprocess.Popen(
            [sys.executable, str(script), part],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=package_env(),
        )
        for part in ('closed_loops', 'replays', 'model_wires')
    ]
    failed = [err.strip().splitlines()[-1] for p in procs if (err := p.communicate()[1]) and p.returncode]
    print(
        f'sma_wrist: numba kernels ready for the workers in {time.perf_counter() - t0:.0f} s'
        + (f' (not all: {"; ".join(failed)})' if failed else ''),
        file=sys.__stderr__,
    )


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Under ``pytest -n 2 --dist loadgroup`` keep the tests that share a module- or class-scoped
    fixture on one worker, so the fixture (the diagnosis cases, the experiment runs: tens of seconds
    each) is built once, not once per worker. One group per set of such fixtures that tests tie
    together, not per module: test_diagnose's open-loop cases (~130 s) and its closed-loop runs (3 x ~10 s)
    share nothing and may run on both workers at once. Tests with only function-scoped
    fixtures stay free to balance the load. Serial runs ignore the mark; tryfirst: before xdist's
    own hook reads it."""
    parent: dict[str, str] = {}

    def root(k: str) -> str:
        while parent.setdefault(k, k) != k:
            k = parent[k]
        return k

    shared: list[tuple[pytest.Item, list[str]]] = []
    for item in items:
        defs = getattr(item, '_fixtureinfo', None)
        module = item.nodeid.split('::')[0]
        names = sorted(
            f'{module}::{name}'
            for name, fds in (defs.name2fixturedefs.items() if defs else ())
            if any(fd.scope in ('module', 'class', 'package') for fd in fds)
        )
        if names:
            shared.append((item, names))
            for n in names[1:]:  # a test using two such fixtures ties their groups together
                parent[root(n)] = root(names[0])
    for item, names in shared:
        item.add_marker(pytest.mark.xdist_group(root(names[0])))


#: the open (turnstile, lock) files of the running test under pytest-xdist, for :func:`alone`
_LOCK_FILES = pytest.StashKey[tuple]()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Under pytest-xdist: every test holds a shared lock from setup to teardown, an ``exclusive``
    one the exclusive lock. A real-time loop (the emulated device on its own wall clock) starved
    by the other worker falls behind and stalls, which is no fault of the code under test. The
    turnstile lets a waiting exclusive test in before the next shared one. A test whose real-time
    part is only a section of it takes the exclusive lock for that section (:func:`alone`), so the
    other worker is not held up by the rest of it. Serial runs: no-op."""
    if 'PYTEST_XDIST_WORKER' not in os.environ:
        yield
        return
    import fcntl

    # the workers' basetemps are <run's basetemp>/popen-gwN: the parent is this run's, shared by all
    base = str(item.config._tmp_path_factory.getbasetemp().parent / 'sma_wrist-xdist')  # type: ignore[attr-defined]
    exclusive = item.get_closest_marker('exclusive') is not None
    with open(base + '.turnstile', 'a') as gate, open(base + '.lock', 'a') as lock:
        fcntl.flock(gate, fcntl.LOCK_EX)
        if exclusive:
            fcntl.flock(lock, fcntl.LOCK_EX)  # holding the gate: no new shared holder gets in
        else:
            fcntl.flock(gate, fcntl.LOCK_UN)
            fcntl.flock(lock, fcntl.LOCK_SH)
            item.stash[_LOCK_FILES] = (gate, lock)
        try:
            yield
        finally:
            if _LOCK_FILES in item.stash:
                del item.stash[_LOCK_FILES]
            fcntl.flock(lock, fcntl.LOCK_UN)
            fcntl.flock(gate, fcntl.LOCK_UN)


@pytest.fixture
def alone(request: pytest.FixtureRequest) -> Callable[[], AbstractContextManager[None]]:
    """``with alone():`` runs a test's wall-clock section as an ``exclusive`` test runs whole: under
    pytest-xdist the other workers finish their current test and wait at the turnstile until the section
    ends. The test's work before and after it (a simulated reference run, the analysis of a bag) runs
    beside the other workers as usual. Serial runs: no-op."""
    import fcntl
    from contextlib import contextmanager

    @contextmanager
    def section() -> Iterator[None]:
        files = request.node.stash.get(_LOCK_FILES, None)
        if files is None:  # a serial run, or a test marked exclusive: already alone
            yield
            return
        gate, lock = files
        fcntl.flock(lock, fcntl.LOCK_UN)  # queue at the turnstile as an exclusive test does
        fcntl.flock(gate, fcntl.LOCK_EX)
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_SH)  # still holding the gate: no exclusive holder gets in between
            fcntl.flock(gate, fcntl.LOCK_UN)

    return section


@pytest.fixture
def ros_shutdown():
    import rclpy

    yield
    rclpy.try_shutdown()


class Probe:
    """Publishes on and listens to contract topics, as a plain rclpy node."""

    def __init__(self, rt: Any, listen: tuple[str, ...] = (), name: str = 'probe', sim_time: bool = False) -> None:
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        from sma_wrist.contract import load_contract
        from sma_wrist.nodes.common import message_class, qos_for

        self.contract = load_contract()
        self.node = rt.add(Node(name, parameter_overrides=[Parameter('use_sim_time', value=sim_time)]))
        self.pubs: dict[str, Any] = {}
        self.got: dict[str, list[Any]] = {t: [] for t in listen + ('/diagnostics',)}
        for t in self.got:
            if t == '/diagnostics':
                from diagnostic_msgs.msg import DiagnosticArray

                self.node.create_subscription(DiagnosticArray, t, self.got[t].append, 10)
            else:
                c = self.contract.topic(t)
                self.node.create_subscription(message_class(c), t, self.got[t].append, qos_for(c))
        self._message_class = message_class
        self._qos_for = qos_for

    def publish(self, topic: str, **fields: Any) -> None:
        c = self.contract.topic(topic)
        if topic not in self.pubs:
            self.pubs[topic] = self.node.create_publisher(self._message_class(c), topic, self._qos_for(c))
        msg = self._message_class(c)(**fields)
        self.pubs[topic].publish(msg)

    def every(self, period_s: float, topic: str, **fields: Any) -> Any:
        """Publish the same message every period (a timer on the probe's clock)."""
        return self.node.create_timer(period_s, lambda: self.publish(topic, **fields))

    def diagnostics(self) -> list[tuple[str, int, str]]:
        return [
            (s.name, s.level[0] if isinstance(s.level, bytes) else int(s.level), s.message)
            for arr in self.got['/diagnostics']
            for s in arr.status
        ]


@pytest.fixture
def probe_factory():
    return Probe
