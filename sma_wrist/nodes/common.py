"""What every sma_wrist node shares: declared parameters with descriptors, contract topics,
input checks and /diagnostics. Plain rclpy (Humble and Jazzy); no runtime detection.

A node lists its parameters as :class:`Param` specs. :class:`WristNode` declares them with
a ``ParameterDescriptor`` (description with unit, ``FloatingPointRange``/``IntegerRange``,
read-only), so rclpy itself rejects wrong types and out-of-range values with its own
reason; the node's ``validate`` adds choice and cross-parameter checks in the on-set
callback and ``apply`` changes state only after everything passed (ros2/demos'
set_parameters_callback pattern).
"""

from __future__ import annotations

import importlib
import math
import os
import signal
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from sma_wrist.contract import Topic, load_contract
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.plant.wrist import PlantParams
from sma_wrist.core.thermal.online import OnlineThermalParams

#: a /diagnostics condition that keeps changing is logged at most this often per key [s]
LOG_THROTTLE_S = 10.0
#: header.frame_id of the per-muscle temperature messages (measured and desired)
MUSCLE_FRAMES = ('muscle_1', 'muscle_2')


@dataclass(frozen=True)
class Param:
    """A declared parameter: default value, unit, description and valid values."""

    name: str
    default: Any
    description: str
    unit: str = ''
    range: tuple[float, float] | None = None  # inclusive, checked by rclpy
    choices: tuple[str, ...] | None = None  # checked by WristNode.validate
    read_only: bool = False
    runtime: bool = True  # False: change needs a restart; rejected with that reason

    def descriptor(self) -> ParameterDescriptor:
        text = self.description + (f' [{self.unit}]' if self.unit else '')
        d = ParameterDescriptor(description=text, read_only=self.read_only)
        if self.choices:
            d.additional_constraints = 'one of: ' + ', '.join(self.choices)
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, bool):
                pass
            elif isinstance(self.default, int):
                d.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
            elif isinstance(self.default, float):
                d.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        return d


def message_class(topic: Topic) -> Any:
    """The ROS message class of a contract topic (e.g. std_msgs.msg.Float64)."""
    return getattr(importlib.import_module(f'{topic.package}.msg'), topic.message)


def qos_for(topic: Topic) -> QoSProfile:
    if topic.qos == 'transient_local':
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=topic.depth,
        reliability=ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.VOLATILE,
    )


#: the chain's pre-load elongation e0 (Eq. 4.17): plant_sim, hysteresis_compensator and adaptive_controller
#: must agree on it; `sma-wrist identify hysteresis` writes the one calibrated for the wire (core/plant/preload.py)
HYSTERESIS_FILE_PARAM = Param(
    'hysteresis_file',
    '',
    'SD-GPI of the wire: hysteresis.yaml from sma-wrist identify hysteresis (empty: the built-in set)',
    runtime=False,
)
PRELOAD_PARAM = Param(
    'preload_elongation_mm',
    PlantParams.preload_elongation_mm,
    "bundle elongation at q_neutral (the chain's pre-load, Eq. 4.17; the same value in plant_sim, "
    "hysteresis_compensator, adaptive_controller and hardware_bridge; the identified wire's in its "
    'wrist_params.yaml, doc/howto/identify_wire.md)',
    'mm',
    (0.1, 10.0),
    runtime=False,
)

#: the online heat-balance estimate (core.thermal.online): the same values in tem_controller and
#: hysteresis_compensator, which each run one on the same samples (doc/explanation/controllers.md)
THERMAL_ADAPTATION_PARAMS = (
    Param(
        'thermal_adaptation.enabled',
        True,
        "estimate the TEMs' drive gain, muscle-face losses and ambient online from the "
        'commands and the thermocouples, and run the observer and law on the estimate (doc/explanation/'
        'controllers.md)',
        runtime=False,
    ),
    Param(
        'thermal_adaptation.apply_after_s',
        OnlineThermalParams.apply_after_s,
        'thermal_adaptation: the estimate is used from this long after the first sample on',
        's',
        (0.0, 600.0),
        runtime=False,
    ),
    Param(
        'thermal_adaptation.tc_lag_s',
        OnlineThermalParams.tc_lag_s,
        "thermal_adaptation: the thermocouple's first-order lag the estimate assumes",
        's',
        (0.0, 5.0),
        runtime=False,
    ),
)


def online_thermal(p: Mapping[str, Any]) -> OnlineThermalParams | None:
    """The estimator's settings from a node's THERMAL_ADAPTATION_PARAMS values; None when it is off."""
    if not p['thermal_adaptation.enabled']:
        return None
    return OnlineThermalParams(
        apply_after_s=p['thermal_adaptation.apply_after_s'], tc_lag_s=p['thermal_adaptation.tc_lag_s']
    )


class WristNode(Node):
    """Base of the sma_wrist nodes: parameters from specs, contract topics, diagnostics."""

    PARAMS: Sequence[Param] = ()
    #: the node publishes /clock and times itself by its own (system) clock; with
    #: use_sim_time it would wait for its own /clock and the whole graph would stop
    OWNS_CLOCK = False

    def __init__(self, name: str, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self.contract = load_contract()
        self._specs = {p.name: p for p in self.PARAMS}
        for p in self.PARAMS:
            self.declare_parameter(p.name, p.default, p.descriptor())
        self.p: dict[str, Any] = {p.name: self.get_parameter(p.name).value for p in self.PARAMS}
        problem = self.validate(self.p) or self._sim_time_problem(self.get_parameter('use_sim_time').value)
        if problem:
            # Bad values from a params file / command line: refuse to start with the reason.
            raise SmaWristError(f'{self.get_name()}: invalid parameters: {problem}')
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._diag_last: dict[str, tuple[int, str]] = {}
        # key -> (last log time [ns], changes not logged since, level last logged)
        self._diag_logged: dict[str, tuple[int | None, int, bytes]] = {}
        self.rejected_inputs = 0

    # -- parameters ------------------------------------------------------------
    def validate(self, values: Mapping[str, Any]) -> str | None:
        """Reason the parameter set is invalid, or None. Override to add cross-checks."""
        for name, v in values.items():
            spec = self._specs.get(name)
            if spec is None:
                continue
            if spec.choices and v not in spec.choices:
                return f'{name} = {v!r} is not one of {", ".join(spec.choices)}'
            if isinstance(v, float) and not math.isfinite(v):
                return f'{name} = {v!r} is not a finite number'
        return None

    def apply(self, changed: Mapping[str, Any]) -> None:
        """Take validated parameter changes into effect. Override."""

    def waiting_for(self, topics: str) -> str:
        """The start-up line's "what it waits for": ``topics``, and /clock first under use_sim_time (a node started
        alone with ``ros2 run`` prints this and then nothing until its inputs come)."""
        clock = '/clock (use_sim_time), then ' if self.get_parameter('use_sim_time').value else ''
        return f'waiting for {clock}{topics}'

    def _sim_time_problem(self, use_sim_time: Any) -> str | None:
        if self.OWNS_CLOCK and use_sim_time is True:
            return (
                f'use_sim_time = true: {self.get_name()} publishes /clock itself and would wait '
                'for its own clock; it must run with use_sim_time false'
            )
        return None

    def _on_set_parameters(self, params: list[Any]) -> SetParametersResult:
        for p in params:
            if p.name == 'use_sim_time':
                problem = self._sim_time_problem(p.value)
                if problem:
                    self.get_logger().warning(f'rejected parameter change: {problem}')
                    return SetParametersResult(successful=False, reason=problem)
        changed = {p.name: p.value for p in params if p.name in self._specs}
        for name in changed:
            if not self._specs[name].runtime:
                return SetParametersResult(
                    successful=False, reason=f'{name} cannot change while running; restart the node'
                )
        candidate = {**self.p, **changed}
        try:
            problem = self.validate(candidate)
            if problem is None:
                self.apply_checked(changed, candidate)
        except SmaWristError as e:
            problem = str(e)
        if problem:
            self.get_logger().warning(f'rejected parameter change: {problem}')
            return SetParametersResult(successful=False, reason=problem)
        return SetParametersResult(successful=True, reason='')

    def apply_checked(self, changed: Mapping[str, Any], candidate: Mapping[str, Any]) -> None:
        old = dict(self.p)
        self.p = dict(candidate)
        try:
            self.apply(changed)
        except SmaWristError:
            self.p = old
            raise

    # -- topics ------------------------------------------------------------------
    def publisher(self, topic_name: str) -> Any:
        t = self.contract.topic(topic_name)
        return self.create_publisher(message_class(t), t.name, qos_for(t))

    def subscription(self, topic_name: str, callback: Callable[[Any], None]) -> Any:
        t = self.contract.topic(topic_name)
        return self.create_subscription(message_class(t), t.name, callback, qos_for(t))

    def now_ns(self) -> int:
        return self.get_clock().now().nanoseconds

    def stamp_s(self, msg: Any) -> float:
        """Time of a measurement [s]: its header stamp, else (unstamped) the node clock.

        Under use_sim_time the node clock only moves when a /clock message has been
        taken, and /clock arrives on its own best-effort subscription, so two samples
        10 ms apart often see the same now() (dt = 0) or 20 ms: control laws must
        difference the stamps the plant (or the device) put on the data.
        """
        st = msg.header.stamp
        if st.sec or st.nanosec:
            return st.sec + 1e-9 * st.nanosec
        return self.now_ns() * 1e-9

    # -- diagnostics ---------------------------------------------------------------
    def diagnostics_stamp(self) -> Any:
        """Stamp of /diagnostics: the node clock; a node that owns /clock overrides it with that time base."""
        return self.get_clock().now().to_msg()

    def publish_status(self, key: str, level: bytes, message: str, values: Mapping[str, Any] | None = None) -> Any:
        """Publish one DiagnosticStatus ``<node>: key`` on /diagnostics now (no log, no change test; a periodic
        status calls this directly); returns its stamp."""
        status = DiagnosticStatus(
            level=level,
            name=f'{self.get_name()}: {key}',
            message=message,
            hardware_id='sma_wrist',
            values=[KeyValue(key=k, value=str(v)) for k, v in (values or {}).items()],
        )
        arr = DiagnosticArray(status=[status])
        arr.header.stamp = stamp = self.diagnostics_stamp()
        self._diag_pub.publish(arr)
        return stamp

    def diagnose(
        self, key: str, level: bytes, message: str, values: Mapping[str, Any] | None = None, *, routine: bool = False
    ) -> None:
        """Publish one DiagnosticStatus when ``key``'s level or message changes, and log it.

        Called every cycle with the current state; publishes on change only, so a
        persistent fault is one message, and its recovery (level OK) another. ``routine``: a state the
        loop is designed to ride through (a command at its limit while the wrist catches up); /diagnostics
        carries it at ``level``, the console only at DEBUG, since a console WARN asks the user to act.
        """
        last = self._diag_last.get(key)
        if last == (level, message):
            return
        if last is None and level == DiagnosticStatus.OK:
            self._diag_last[key] = (level, message)
            return
        self._diag_last[key] = (level, message)
        stamp = self.publish_status(key, level, message, values)
        # the log follows /diagnostics: an error's onset and its end are always logged, and so is the end of any
        # problem whose onset was logged (a TEM off for 0.23 s logged its WARN, and its "commands fresh" fell in the
        # throttle: the console read as if it stayed off); any other change (a command touching its limit every few
        # ticks, an error text carrying a measured value) at most once per LOG_THROTTLE_S per key, with the count of
        # changes not logged. Time is that of the /diagnostics stamp: hardware_bridge's own (steady) clock is none
        # of the graph's, and on the embedded runtime it lags the device
        now = stamp.sec * 1_000_000_000 + stamp.nanosec
        t_last, quiet, logged_level = self._diag_logged.get(key, (None, 0, DiagnosticStatus.OK))
        was_error = last is not None and last[0] == DiagnosticStatus.ERROR
        edge = was_error != (level == DiagnosticStatus.ERROR)
        recovered = level == DiagnosticStatus.OK and logged_level != DiagnosticStatus.OK
        if not (edge or recovered) and t_last is not None and now - t_last < LOG_THROTTLE_S * 1e9:
            self._diag_logged[key] = (t_last, quiet + 1, logged_level)
            return
        self._diag_logged[key] = (now, 0, level)
        text = f'{key}: {message}' + (
            f' ({quiet} more changes in the last {LOG_THROTTLE_S:g} s, see /diagnostics)' if quiet else ''
        )
        log = self.get_logger()
        if routine:
            log.debug(text)
        elif level == DiagnosticStatus.OK:
            log.info(text)
        elif level == DiagnosticStatus.WARN:
            log.warning(text)
        else:
            log.error(text)

    def reject_input(self, topic: str, reason: str) -> None:
        """Count and report a malformed message; the last good value stays in use."""
        self.rejected_inputs += 1
        self.diagnose(
            f'input {topic}',
            DiagnosticStatus.WARN,
            f'rejected message: {reason}',
            {'rejected_total': self.rejected_inputs},
        )


def finite(*values: float) -> bool:
    """Every value a finite int or float."""
    for v in values:  # a loop, not all(<generator>): called for every incoming sample
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            return False
    return True


class Freshness:
    """Time of the last good sample per input, to detect stale sensors."""

    def __init__(self, node: WristNode, names: Sequence[str]) -> None:
        self.node = node
        self.stamp_ns: dict[str, int | None] = {n: None for n in names}

    def mark(self, name: str) -> None:
        self.stamp_ns[name] = self.node.now_ns()

    def stale(self, timeout_s: float, since_ns: int | None = None) -> list[str]:
        """The inputs with no good sample for more than ``timeout_s`` [s]. One never received is stale at once, or,
        given ``since_ns`` (node clock [ns] at which waiting for it began), once ``timeout_s`` has passed since."""
        now = self.node.now_ns()
        out = []
        for name, t in self.stamp_ns.items():
            t = since_ns if t is None else t
            if t is None or now - t > timeout_s * 1e9:
                out.append(name)
        return out

    def seen_all(self) -> bool:
        return all(t is not None for t in self.stamp_ns.values())


class _ShutdownRequest:
    """Remembers that SIGINT arrived, for the duration of :func:`main_for`.

    Installed before ``rclpy.init``, so Humble's rclpy signal handler chains to it (it calls
    the handler it replaced). rclpy shuts the context down on a separate thread, so right
    after a Ctrl-C ``rclpy.ok()`` can still be true while a callback or rclpy's own
    ``take_message`` already failed on the interrupted call (seen 1 launch in 6 on Humble:
    ``RuntimeError: Unable to convert call argument '0'``). Raises KeyboardInterrupt like
    Python's default handler.
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous: Any = None
        self._installed = False

    def install(self) -> _ShutdownRequest:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._on_sigint)
            self._installed = True
        return self

    def _on_sigint(self, signum: int, frame: Any) -> None:
        self.requested = True
        if frame is not None and (
            frame.f_code.co_name == '__del__' or f'{os.sep}llvmlite{os.sep}' in frame.f_code.co_filename
        ):
            # where Python prints an exception raised there with a traceback and drops it: a finaliser ("Exception
            # ignored in ... __del__", rclpy's Future.__del__ during a collection, seen under Humble with `timeout -s
            # INT ros2 launch`) and llvmlite's ctypes callback while a node compiles its kernels ("Exception ignored
            # on calling ctypes callback function", seen under Humble: Ctrl-C during plant_sim's first compile). The
            # request is noted: rclpy's handler, which called this one, has shut the context down, so spin ends on
            # ExternalShutdownException, and main_for stops a node that was still being built
            return
        raise KeyboardInterrupt

    def restore(self) -> None:
        if self._installed:
            signal.signal(signal.SIGINT, self._previous)
            self._installed = False

    def finish(self) -> None:
        """Before the teardown: after a SIGINT, further ones are the same request and are ignored
        (under ros2 launch a node gets the terminal's Ctrl-C twice and launch's own; one arriving
        while the interpreter finalises, which resets Python handlers to the default, killed the
        exiting node: exit -2, seen under Humble). SIG_IGN survives finalisation. Else restore."""
        if self._installed and self.requested:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        else:
            self.restore()


def _teardown(node: Any) -> None:
    """Destroy the node and shut rclpy down, each step even if a further Ctrl-C interrupts one.

    A second SIGINT lands here whenever a user presses Ctrl-C twice or a supervisor signals
    the process group as well as launch (``timeout -s INT``): it is the same request to stop,
    not an error, so it must not turn a clean exit into a traceback.
    """
    steps = ([node.destroy_node] if node is not None else []) + [rclpy.try_shutdown]
    for step in steps:
        try:
            step()
        except KeyboardInterrupt:
            pass


def _parameter_reason(e: Exception) -> str:
    """rclpy's parameter exceptions pass (message, parameter) to Exception: name the parameter first."""
    if len(e.args) >= 2:
        return f'invalid parameter {e.args[1]}: {e.args[0]}'
    return f'invalid parameter: {e.args[0] if e.args else e}'


def start_up_refusal(e: BaseException, node_class: type) -> str | None:
    """The one-line reason a node refuses to start (its process exits 2), or None if ``e`` is none.

    A ParameterException is an override of the wrong type (payload_kg:=1 for a double: write
    1.0) or out of its descriptor's range, from --params-file or -p: rclpy refuses it in
    declare_parameter.
    """
    if isinstance(e, SmaWristError):
        return f'error: {e}'
    if isinstance(e, ParameterException):
        return f'error: {getattr(node_class, "__name__", "node")}: {_parameter_reason(e)}'
    return None


def add_or_refuse(rt: Any, node_class: type) -> Any:
    """``rt.add(node_class)`` on an embedded Runtime; a refusal to start is a ParameterError with its one-line reason.

    The in-process tools (``sma-wrist run``, ``experiment``, ``sweep``) build the nodes the way
    ``ros2 run`` does; an override rclpy refuses in declare_parameter (out of its range, wrong
    type) must reach the user as that reason, not as a traceback. A ParameterError (unlike
    rclpy's exceptions) also pickles, so it crosses experiment's process pool intact.
    """
    from sma_wrist.core.errors import ParameterError

    try:
        return rt.add(node_class)
    except ParameterError:
        raise
    except Exception as e:  # noqa: BLE001 - start_up_refusal says which ones are the node's refusal
        why = start_up_refusal(e, node_class)
        if why is None:
            raise
        raise ParameterError(why.removeprefix('error: ')) from None


#: the package's nodes (setup.py's console scripts; test_config checks they agree)
NODE_NAMES = (
    'plant_sim',
    'hardware_bridge',
    'trajectory_generator',
    'adaptive_controller',
    'hysteresis_compensator',
    'tem_controller',
    'twin_monitor',
)


def undeclared_parameters(params_files: Sequence[str | Path], declared: Mapping[str, set[str]]) -> list[str]:
    """Keys of ``params_files`` under a node of ``declared`` ({node name: its parameter names}), or under ``/**``,
    that no such node declares, and node names that are none of the package's (:data:`NODE_NAMES`): ROS ignores
    them, so a misspelt name runs the defaults in silence."""
    from sma_wrist.runtime.arguments import load_params_file

    everyone = set().union(*declared.values()) | {'use_sim_time'}
    out, strangers = [], []
    for f in params_files:
        for rule in load_params_file(f):
            node = rule.node.strip('/')
            if '*' not in node and node.rsplit('/', 1)[-1] not in NODE_NAMES:  # a namespace before it is the user's
                if (rule.node, f) not in strangers:
                    strangers.append((rule.node, f))
                continue
            names = everyone if node in ('**', '*') else declared[node] | {'use_sim_time'} if node in declared else None
            if names is not None and rule.name not in names:
                out.append(f'{rule.name} under {rule.node} in {f}')
    return out + [f'node {node} in {f} (the nodes are {", ".join(NODE_NAMES)})' for node, f in strangers]


def refuse_undeclared(params_files: Sequence[str | Path], declared: Mapping[str, set[str]]) -> None:
    """ParameterError listing :func:`undeclared_parameters`, if any (the in-process tools' rule: ``run``,
    ``experiment``, ``sweep``)."""
    from sma_wrist.core.errors import ParameterError

    unknown = undeclared_parameters(params_files, declared)
    if unknown:
        raise ParameterError('not a parameter of the node graph (misspelt?): ' + '; '.join(unknown))


def main_for(node_class: type, args: Sequence[str] | None = None) -> int:
    """ros2/demos-style main: init, spin, clean shutdown; errors reported, not tracebacks.

    Returns 0 after Ctrl-C / an external shutdown (also when a second Ctrl-C interrupts the
    teardown), 2 when the node refuses its parameters.
    """
    shutdown = _ShutdownRequest().install()
    node = None
    try:
        rclpy.init(args=args)
        node = node_class()
        if shutdown.requested:  # a Ctrl-C while the node was built (compiling) was only noted: _on_sigint
            raise KeyboardInterrupt
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except (SmaWristError, ParameterException) as e:
        print(start_up_refusal(e, node_class), flush=True)
        return 2
    except Exception:
        # Ctrl-C: rclpy's signal handler shuts the context down, and a callback that is
        # publishing at that moment raises (Humble: RCLError "publisher's context is
        # invalid", or take_message's RuntimeError). That is the shutdown that was asked
        # for, not a failure.
        if rclpy.ok() and not shutdown.requested:
            raise
    finally:
        shutdown.finish()
        _teardown(node)
    return 0


__all__ = [
    'NODE_NAMES',
    'Param',
    'WristNode',
    'Freshness',
    'add_or_refuse',
    'finite',
    'main_for',
    'message_class',
    'qos_for',
    'start_up_refusal',
]
