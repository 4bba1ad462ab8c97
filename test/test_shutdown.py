"""Node processes end cleanly however they are asked to stop.

Each case runs ``main_for`` in a child process with real signals (a SIGINT to itself, as
the kernel sends a user's Ctrl-C), on the embedded runtime: a KeyboardInterrupt raised in
the parent pytest process would end the test run instead of failing a test.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import pytest

_PRELUDE = """
import os, signal, sys
# an interactive shell's foreground job: SIGINT raises KeyboardInterrupt (a child started
# from a background job would inherit SIGINT ignored)
signal.signal(signal.SIGINT, signal.default_int_handler)
from sma_wrist import runtime
runtime.activate(force=True)
import rclpy
from rclpy.node import Node
from sma_wrist.nodes.common import main_for

def ctrl_c():
    os.kill(os.getpid(), signal.SIGINT)
"""


def _run(body: str, after: str = '') -> subprocess.CompletedProcess:
    code = (
        _PRELUDE
        + textwrap.dedent(body)
        + """
rc = main_for(Subject, ['subject'])
"""
        + after
        + """
print('rclpy.ok after main_for:', rclpy.ok(), flush=True)
sys.exit(rc)
"""
    )
    return subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60)


def test_second_ctrl_c_while_destroying_the_node_exits_0_without_traceback():
    p = _run("""
    class Subject(Node):
        def __init__(self):
            super().__init__('subject')
            self.create_timer(0.01, ctrl_c)             # the user's Ctrl-C while spinning
        def destroy_node(self):
            ctrl_c()                                    # and a second one during the teardown
            super().destroy_node()
    """)
    assert p.returncode == 0, p.stderr
    assert 'Traceback' not in p.stderr
    assert 'rclpy.ok after main_for: False' in p.stdout  # rclpy was still shut down


def test_a_third_ctrl_c_while_the_process_exits_does_not_kill_it():
    # under ros2 launch a node gets the terminal's SIGINT twice and launch's forwarded one: seen
    # under Humble, the last arrived after main_for returned and the node died with exit -2
    p = _run(
        """
    class Subject(Node):
        def __init__(self):
            super().__init__('subject')
            self.create_timer(0.01, ctrl_c)
        def destroy_node(self):
            ctrl_c()
            super().destroy_node()
    """,
        after='ctrl_c()\nctrl_c()',
    )
    assert p.returncode == 0, (p.returncode, p.stderr)
    assert 'Traceback' not in p.stderr and 'rclpy.ok after main_for: False' in p.stdout


def test_take_message_runtime_error_after_ctrl_c_exits_0():
    # Humble under load: the signal lands inside rclpy's take_message, pybind11 turns it into
    # a RuntimeError, and rclpy.ok() is still true because rclpy shuts the context down on
    # its own thread a moment later
    p = _run("""
    class Subject(Node):
        def __init__(self):
            super().__init__('subject')
            self.create_timer(0.01, self.take)
        def take(self):
            try:
                ctrl_c()
            except KeyboardInterrupt:
                raise RuntimeError("Unable to convert call argument '0' of type 'object' to Python object")
    """)
    assert p.returncode == 0, p.stderr
    assert 'Traceback' not in p.stderr


def test_a_failure_without_a_shutdown_request_is_not_hidden():
    p = _run("""
    class Subject(Node):
        def __init__(self):
            super().__init__('subject')
            self.create_timer(0.01, self.fail)
        def fail(self):
            raise RuntimeError('a real bug')
    """)
    assert p.returncode == 1
    assert 'RuntimeError: a real bug' in p.stderr
    assert 'rclpy.ok after main_for' not in p.stdout


@pytest.mark.parametrize(
    'argv, expected',
    [
        (
            ['-p', 'payload_kg:=5.0'],
            'error: PlantSim: invalid parameter payload_kg: Invalid parameter value (5.0) '
            'for parameter. Reason: Parameter payload_kg out of range',
        ),
        (
            ['-p', 'payload_kg:=1'],
            "error: PlantSim: invalid parameter: Trying to set parameter 'payload_kg' to '1' "
            "of type 'INTEGER', expecting type 'DOUBLE'\n",
        ),
    ],
)
def test_start_up_refusal_names_the_parameter_before_the_reason(capsys, argv, expected):
    from sma_wrist.nodes.common import main_for
    from sma_wrist.nodes.plant_sim import PlantSim

    assert main_for(PlantSim, ['plant_sim', '--ros-args', *argv]) == 2
    out = capsys.readouterr().out
    assert out.startswith(expected)
    assert not out.rstrip().endswith('payload_kg')  # Humble's exception args were joined message-first


def test_ctrl_c_inside_a_finaliser_is_not_raised_there():
    """Humble, `timeout -s INT ros2 launch`: the SIGINT landed in rclpy's Future.__del__, where a raised
    KeyboardInterrupt is printed as "Exception ignored in ... __del__" with a traceback and dropped.
    There the request is only noted (rclpy's own handler has shut the context down); anywhere else it
    raises as Python's default handler does."""
    from sma_wrist.nodes.common import _ShutdownRequest

    frames = []

    class Finalised:
        def __del__(self) -> None:
            frames.append(sys._getframe())

    Finalised()  # collected at once: its __del__ frame is kept
    req = _ShutdownRequest()
    req._on_sigint(2, frames[0])
    assert req.requested
    with pytest.raises(KeyboardInterrupt):
        _ShutdownRequest()._on_sigint(2, sys._getframe())


def test_ctrl_c_inside_a_kernel_compile_callback_is_noted_and_the_node_stops_once_built(tmp_path):
    """Humble: a Ctrl-C while plant_sim compiled its kernels at start-up landed in llvmlite's ctypes callback, where a
    raised KeyboardInterrupt is printed as "Exception ignored on calling ctypes callback function" with a traceback
    and dropped. There it is only noted; the node stops once it is built instead of spinning."""
    import os

    from sma_wrist.nodes import common

    namespace: dict = {'sys': sys}
    exec(
        compile('def callback():\n    return sys._getframe()', os.path.join('x', 'llvmlite', 'ee.py'), 'exec'),
        namespace,
    )
    req = common._ShutdownRequest()
    req._on_sigint(2, namespace['callback']())
    assert req.requested

    spun = []

    class Compiling:
        """A node whose construction gets the Ctrl-C inside the compile callback."""

        def __init__(self) -> None:
            # the handler main_for installed, called as the signal would call it there
            signal.getsignal(signal.SIGINT)(signal.SIGINT, namespace['callback']())

    class Rclpy:
        def init(self, args=None) -> None:
            pass

        def spin(self, node) -> None:
            spun.append(node)

        def ok(self) -> bool:
            return True

    orig, orig_teardown = common.rclpy, common._teardown
    common.rclpy, common._teardown = Rclpy(), lambda node: None
    try:
        assert common.main_for(Compiling) == 0
    finally:
        common.rclpy, common._teardown = orig, orig_teardown
        signal.signal(signal.SIGINT, signal.default_int_handler)
    assert spun == []


def test_ctrl_c_shuts_the_context_down_before_the_node_is_destroyed_as_rclpy_does():
    """rclpy's SIGINT handler shuts the context down, then Python's raises KeyboardInterrupt: a node publishing in
    its teardown gets "publisher's context is invalid" under ROS 2, and so on the embedded runtime (a twin monitor
    that published there exited 1 with a traceback at every Ctrl-C under Humble and 0 here)."""
    p = _run("""
    from std_msgs.msg import Float64
    class Subject(Node):
        def __init__(self):
            super().__init__('subject')
            self.pub = self.create_publisher(Float64, '/x', 10)
            self.create_timer(0.01, ctrl_c)
        def destroy_node(self):
            print('ok in teardown:', rclpy.ok(), flush=True)
            try:
                self.pub.publish(Float64(data=1.0))
            except RuntimeError as e:
                print('publish in teardown:', type(e).__name__, e, flush=True)
            super().destroy_node()
    """)
    assert p.returncode == 0, p.stderr
    assert 'ok in teardown: False' in p.stdout
    assert "publish in teardown: RCLError publisher's context is invalid" in p.stdout


def test_in_process_tools_keep_their_own_ctrl_c_handling():
    """``Runtime`` (run, experiment, sweep) stops the graph itself on Ctrl-C and keeps the bag: it installs no
    handler that would shut the context down under it."""
    import signal

    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.runtime.launch import Runtime

    before = signal.getsignal(signal.SIGINT)
    with Runtime():
        assert signal.getsignal(signal.SIGINT) is before
    assert signal.getsignal(signal.SIGINT) is before
