"""Every node compiles its numba kernels before it takes part in the loop, not in its first callbacks.

Under ros2 launch each node is a process on the wall clock: a kernel compiled inside a callback stalls that
node for seconds on a cold cache (the first launch after an install) while plant_sim goes on simulating, and
the TEMs went off ("no fresh command on tem_1, tem_2: TEM off" 4.5 s into the first launch). The check is the
mechanism: in a fresh interpreter, no kernel of the package gets its first compiled signature (compiled or
loaded from numba's cache) after the nodes were constructed.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from sma_wrist.core.jit import AVAILABLE

SCRIPT = r"""
import json, sys
from sma_wrist import runtime
runtime.activate()
from numba.core.registry import CPUDispatcher
from sma_wrist.closed_loop import graph_nodes, overrides, ros_args
from sma_wrist.nodes.common import add_or_refuse
from sma_wrist.runtime.launch import Runtime
from sma_wrist.runtime.rclpy import logging as rlog

def signatures():
    return {f'{v.py_func.__module__}.{v.__name__}': len(v.signatures) for name, mod in list(sys.modules.items())
            if name.startswith('sma_wrist') for v in list(vars(mod).values()) if isinstance(v, CPUDispatcher)}

found = {}
soon = {'thermal_adaptation.apply_after_s': 1.0}  # the online estimate in use from 1 s on, not 10 s
# fewest nodes first: a kernel one mode compiles late must not be hidden by another mode's start-up
for mode in ('pid', 'direct_adaptive', 'inverse_adaptive'):
    with rlog.silenced(), Runtime(ros_args(), params=overrides(mode, 0.3, extra={
            '/tem_controller': soon, '/hysteresis_compensator': soon})) as rt:
        for cls in graph_nodes(mode):
            add_or_refuse(rt, cls)
        before = signatures()
        rt.run_until(3.5, until='sim')  # the estimate's first window closes at ~2 s
        found[mode] = sorted(k for k, n in signatures().items() if n > before.get(k, 0))
print(json.dumps(found))
"""


@pytest.mark.skipif(not AVAILABLE, reason='without numba nothing is compiled')
def test_no_kernel_is_compiled_inside_the_loop():
    r = subprocess.run([sys.executable, '-c', SCRIPT], capture_output=True, text=True, timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    found = json.loads(r.stdout.splitlines()[-1])
    assert found == {'pid': [], 'direct_adaptive': [], 'inverse_adaptive': []}, found
