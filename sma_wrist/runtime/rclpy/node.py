"""rclpy.node.Node for the embedded runtime.

Parameter handling follows rclpy/node.py (Humble) step by step: declare_parameters infers
a static type from the default unless ``dynamic_typing``, overrides (params files, ``-p``,
``parameter_overrides``) replace the default, descriptors are applied (read-only, type,
FloatingPointRange/IntegerRange with step and rclpy's tolerance ``PARAM_REL_TOL``), then
the on-set-parameters callbacks (newest first) may reject with a reason, and a
ParameterEvent is published on /parameter_events.  Reason strings are rclpy's.

One deliberate choice: overrides are looked up by the *full* (namespace-prefixed) name in
``declare_parameters(namespace, ...)``, as Jazzy does; Humble looks up the bare name.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Callable, Iterator
from typing import Any

from sma_wrist.runtime.arguments import RosArguments, overrides_for, parse_ros_args
from sma_wrist.runtime.messages import get_message_class, is_message_class

from .callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from .clock import Clock, ROSClock
from .constants import S_TO_NS
from .context import Context
from .exceptions import (
    InvalidNamespaceException,
    InvalidNodeNameException,
    InvalidParameterException,
    InvalidParameterTypeException,
    InvalidParameterValueException,
    InvalidTopicNameException,
    NotInitializedException,
    ParameterAlreadyDeclaredException,
    ParameterImmutableException,
    ParameterNotDeclaredException,
    ParameterUninitializedException,
)
from .logging import RcutilsLogger, get_logger
from .parameter import PARAMETER_SEPARATOR_STRING, Parameter
from .publisher import Publisher
from .qos import QoSProfile, qos_profile_parameter_events
from .subscription import Subscription
from .time_source import TimeSource
from .timer import Timer
from .utilities import get_default_context

ParameterDescriptor = get_message_class('rcl_interfaces/msg/ParameterDescriptor')
ParameterEvent = get_message_class('rcl_interfaces/msg/ParameterEvent')
ParameterValue = get_message_class('rcl_interfaces/msg/ParameterValue')
ParameterMsg = get_message_class('rcl_interfaces/msg/Parameter')
SetParametersResult = get_message_class('rcl_interfaces/msg/SetParametersResult')
FloatingPointRange = get_message_class('rcl_interfaces/msg/FloatingPointRange')
IntegerRange = get_message_class('rcl_interfaces/msg/IntegerRange')
ParameterType = get_message_class('rcl_interfaces/msg/ParameterType')

_NODE_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
_NS_TOKEN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')
_TOPIC_CHARS = re.compile(r'[A-Za-z0-9_/~{}]*')


def validate_node_name(name: str) -> None:
    if not name:
        raise InvalidNodeNameException(name, 'node name must not be empty', 0)
    if not _NODE_NAME.fullmatch(name):
        bad = next((i for i, c in enumerate(name) if not (c.isalnum() or c == '_')), 0)
        if name[0].isdigit():
            raise InvalidNodeNameException(name, 'node name must not start with a number', 0)
        raise InvalidNodeNameException(
            name, "node name must not contain characters other than alphanumerics or '_'", bad
        )


def validate_namespace(namespace: str) -> None:
    if not namespace.startswith('/'):
        raise InvalidNamespaceException(namespace, 'namespace must be absolute', 0)
    if namespace == '/':
        return
    if namespace.endswith('/'):
        raise InvalidNamespaceException(namespace, "namespace must not end with a '/'", len(namespace) - 1)
    for token in namespace[1:].split('/'):
        if not _NS_TOKEN.fullmatch(token):
            raise InvalidNamespaceException(
                namespace,
                'namespace tokens must be non-empty alphanumerics/underscore not starting with a number',
                namespace.find(token),
            )


def validate_parameter_name(name: str) -> None:
    if not isinstance(name, str) or not name:
        raise InvalidParameterException(name)


def expand_topic_name(topic: str, node_name: str, namespace: str) -> str:
    """rcl_expand_topic_name: ~ and {node}/{ns} substitution, relative names get the ns."""
    if not topic:
        raise InvalidTopicNameException(topic, 'topic name must not be empty', 0)
    fqn = namespace.rstrip('/') + '/' + node_name
    name = topic.replace('{node}', node_name).replace('{ns}', namespace.rstrip('/') or '/')
    if name.startswith('~'):
        name = fqn + name[1:]
    elif not name.startswith('/'):
        name = namespace.rstrip('/') + '/' + name
    if (
        not _TOPIC_CHARS.fullmatch(name)
        or '//' in name
        or (name.endswith('/') and name != '/')
        or '~' in name
        or '{' in name
        or '}' in name
    ):
        bad = next((i for i, c in enumerate(name) if not (c.isalnum() or c in '_/')), 0)
        raise InvalidTopicNameException(topic, 'topic name is invalid', bad)
    for token in name[1:].split('/'):
        if token and token[0].isdigit():
            raise InvalidTopicNameException(topic, 'topic tokens must not start with a number', name.find(token))
    return name


class Node:
    """A Node in the (embedded, in-process) ROS graph."""

    PARAM_REL_TOL = 1e-6

    def __init__(
        self,
        node_name: str,
        *,
        context: Context | None = None,
        cli_args: list[str] | None = None,
        namespace: str | None = None,
        use_global_arguments: bool = True,
        enable_rosout: bool = True,
        start_parameter_services: bool = True,
        parameter_overrides: list[Parameter] | None = None,
        allow_undeclared_parameters: bool = False,
        automatically_declare_parameters_from_overrides: bool = False,
    ) -> None:
        self._context = get_default_context() if context is None else context
        self._parameters: dict[str, Parameter] = {}
        self._publishers: list[Publisher] = []
        self._subscriptions: list[Subscription] = []
        self._timers: list[Timer] = []
        self._clients: list[Any] = []
        self._services: list[Any] = []
        self._guards: list[Any] = []
        self._default_callback_group = MutuallyExclusiveCallbackGroup()
        self._rate_group = ReentrantCallbackGroup()
        self._parameters_callbacks: list[Callable[[list[Parameter]], Any]] = []
        self._allow_undeclared_parameters = allow_undeclared_parameters
        self._parameter_overrides: dict[str, Parameter] = {}
        self._descriptors: dict[str, Any] = {}
        self._executor: Any = None
        self._destroyed = False

        if not self._context.ok():
            raise NotInitializedException('cannot create node')
        self._local_args: RosArguments = parse_ros_args(cli_args)
        self._arg_sources: list[RosArguments] = ([self._context.args] if use_global_arguments else []) + [
            self._local_args
        ]

        namespace = namespace or ''
        # __node / __ns remaps: local rules before global ones (rcl_remap_node_name)
        for src in reversed(self._arg_sources):
            for rule in src.remaps:
                if rule.node not in (None, node_name):
                    continue
                if rule.src in ('__node', '__name'):
                    node_name = rule.dst
                    break
        validate_node_name(node_name)
        for src in reversed(self._arg_sources):
            ns_rules = [r for r in src.remaps if r.src == '__ns' and r.node in (None, node_name)]
            if ns_rules:
                namespace = ns_rules[0].dst
                break
        if not namespace:
            namespace = '/'
        if not namespace.startswith('/'):
            namespace = '/' + namespace
        validate_namespace(namespace)
        self._node_name = node_name
        self._namespace = namespace
        self._fqn = namespace.rstrip('/') + '/' + node_name
        self._logger = get_logger(
            (namespace.strip('/').replace('/', '.') + '.' if namespace != '/' else '') + node_name
        )

        graph = self._context.graph
        graph.nodes.append(self)
        # Clock that has support for ROS time (needed by publishers for tap timestamps).
        self._clock = ROSClock()

        self._parameter_event_publisher = self.create_publisher(
            ParameterEvent, '/parameter_events', qos_profile_parameter_events
        )

        for name, value in overrides_for(self._fqn, self._arg_sources).items():
            self._parameter_overrides[name] = Parameter(name, value=value)
        if parameter_overrides is not None:
            self._parameter_overrides.update({p.name: p for p in parameter_overrides})

        if automatically_declare_parameters_from_overrides:
            self.declare_parameters(
                '',
                [(name, param.value, ParameterDescriptor()) for name, param in self._parameter_overrides.items()],
                ignore_override=True,
            )

        self._time_source = TimeSource(node=self)
        self._time_source.attach_clock(self._clock)

    # -- properties --------------------------------------------------------
    @property
    def publishers(self) -> Iterator[Publisher]:
        yield from self._publishers

    @property
    def subscriptions(self) -> Iterator[Subscription]:
        yield from self._subscriptions

    @property
    def timers(self) -> Iterator[Timer]:
        yield from self._timers

    @property
    def clients(self) -> Iterator[Any]:
        yield from self._clients

    @property
    def services(self) -> Iterator[Any]:
        yield from self._services

    @property
    def guards(self) -> Iterator[Any]:
        yield from self._guards

    @property
    def waitables(self) -> Iterator[Any]:
        yield from ()

    @property
    def executor(self) -> Any:
        return self._executor

    @executor.setter
    def executor(self, new_executor: Any) -> None:
        current = self._executor
        if current is new_executor:
            return
        if current is not None:
            current.remove_node(self)
        if new_executor is not None:
            new_executor.add_node(self)
        self._executor = new_executor

    @property
    def context(self) -> Context:
        return self._context

    @property
    def default_callback_group(self) -> CallbackGroup:
        return self._default_callback_group

    @property
    def handle(self) -> Node:
        return self

    def _wake_executor(self) -> None:
        self._context.graph.version += 1

    def get_name(self) -> str:
        return self._node_name

    def get_namespace(self) -> str:
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        return self._fqn

    def get_clock(self) -> Clock:
        return self._clock

    def get_logger(self) -> RcutilsLogger:
        return self._logger

    # -- parameters --------------------------------------------------------
    def declare_parameter(
        self, name: str, value: Any = None, descriptor: Any = None, ignore_override: bool = False
    ) -> Parameter:
        if value is None and descriptor is None:
            args: tuple[Any, ...] = (name,)
        else:
            descriptor = ParameterDescriptor() if descriptor is None else descriptor
            args = (name, value, descriptor)
        return self.declare_parameters('', [args], ignore_override)[0]

    def declare_parameters(
        self,
        namespace: str,
        parameters: list[tuple[str] | tuple[str, Parameter.Type] | tuple[str, Any, Any]],
        ignore_override: bool = False,
    ) -> list[Parameter]:
        parameter_list: list[Parameter] = []
        descriptors: dict[str, Any] = {}
        for index, parameter_tuple in enumerate(parameters):
            if len(parameter_tuple) < 1 or len(parameter_tuple) > 3:
                raise TypeError(
                    f'Invalid parameter tuple length at index {index} in parameters list: '
                    f'{parameter_tuple}; expecting length between 1 and 3'
                )
            value = None
            name = parameter_tuple[0]
            second_arg = parameter_tuple[1] if 1 < len(parameter_tuple) else None
            descriptor = parameter_tuple[2] if 2 < len(parameter_tuple) else ParameterDescriptor()
            if not isinstance(name, str):
                raise TypeError(f'First element {name} at index {index} in parameters list is not a str.')
            if not isinstance(descriptor, ParameterDescriptor):
                raise TypeError(
                    f'Third element {descriptor} at index {index} in parameters list is not a ParameterDescriptor.'
                )
            if len(parameter_tuple) == 1:
                warnings.warn(
                    f"when declaring parameter named '{name}', declaring a parameter only "
                    'providing its name is deprecated.',
                    stacklevel=3,
                )
                descriptor.dynamic_typing = True

            if isinstance(second_arg, Parameter.Type):
                if second_arg == Parameter.Type.NOT_SET:
                    raise ValueError(f'Cannot declare parameter {{{name}}} as statically typed of type NOT_SET')
                if descriptor.dynamic_typing is True:
                    raise ValueError(
                        f'When declaring parameter {{{name}}} passing a descriptor with'
                        '`dynamic_typing=True` is not allowed when the parameter type is provided'
                    )
                descriptor.type = second_arg.value
            else:
                value = second_arg
                if not descriptor.dynamic_typing and value is not None:
                    if isinstance(value, ParameterValue):
                        if value.type == ParameterType.PARAMETER_NOT_SET:
                            raise ValueError(
                                'Cannot declare a statically typed parameter with '
                                'default value of type PARAMETER_NOT_SET'
                            )
                        descriptor.type = value.type
                    else:
                        descriptor.type = Parameter.Type.from_parameter_value(value).value
            if isinstance(value, ParameterValue):
                from .parameter import parameter_value_to_python

                value = parameter_value_to_python(value)

            if namespace:
                name = f'{namespace}.{name}'
            if not ignore_override and name in self._parameter_overrides:
                value = self._parameter_overrides[name].value
            validate_parameter_name(name)
            parameter_list.append(Parameter(name, value=value))
            descriptors[name] = descriptor

        already = [p.name for p in parameter_list if p.name in self._parameters]
        if already:
            raise ParameterAlreadyDeclaredException(already)
        self._set_parameters(parameter_list, descriptors, raise_on_failure=True, allow_undeclared_parameters=True)
        return [self._parameters[p.name] for p in parameter_list]

    def undeclare_parameter(self, name: str) -> None:
        if self.has_parameter(name):
            if self._descriptors[name].read_only:
                raise ParameterImmutableException(name)
            del self._parameters[name]
            del self._descriptors[name]
        else:
            raise ParameterNotDeclaredException(name)

    def has_parameter(self, name: str) -> bool:
        return name in self._parameters

    def get_parameter_types(self, names: list[str]) -> list[Any]:
        if not all(isinstance(n, str) for n in names):
            raise TypeError('All names must be instances of type str')
        return [self.get_parameter_type(n) for n in names]

    def get_parameter_type(self, name: str) -> Any:
        if self.has_parameter(name):
            return self._parameters[name].type_.value
        if self._allow_undeclared_parameters:
            return Parameter.Type.NOT_SET
        raise ParameterNotDeclaredException(name)

    def get_parameters(self, names: list[str]) -> list[Parameter]:
        if not all(isinstance(n, str) for n in names):
            raise TypeError('All names must be instances of type str')
        return [self.get_parameter(n) for n in names]

    def get_parameter(self, name: str) -> Parameter:
        if self.has_parameter(name):
            parameter = self._parameters[name]
            if parameter.type_ != Parameter.Type.NOT_SET or self._descriptors[name].dynamic_typing:
                return parameter
            raise ParameterUninitializedException(name)
        if self._allow_undeclared_parameters:
            return Parameter(name, Parameter.Type.NOT_SET, None)
        raise ParameterNotDeclaredException(name)

    def get_parameter_or(self, name: str, alternative_value: Parameter | None = None) -> Parameter:
        if alternative_value is None:
            alternative_value = Parameter(name, Parameter.Type.NOT_SET)
        if not self.has_parameter(name):
            return alternative_value
        if self._parameters[name].type_ == Parameter.Type.NOT_SET:
            return alternative_value
        return self._parameters[name]

    def get_parameters_by_prefix(self, prefix: str) -> dict[str, Parameter]:
        if prefix:
            prefix = prefix + PARAMETER_SEPARATOR_STRING
        n = len(prefix)
        return {k[n:]: v for k, v in self._parameters.items() if k.startswith(prefix)}

    def set_parameters(self, parameter_list: list[Parameter]) -> list[Any]:
        return self._set_parameters(parameter_list)

    def _set_parameters(
        self,
        parameter_list: list[Parameter],
        descriptors: dict[str, Any] | None = None,
        raise_on_failure: bool = False,
        allow_undeclared_parameters: bool = False,
    ) -> list[Any]:
        results = []
        for param in parameter_list:
            if not allow_undeclared_parameters:
                self._check_undeclared_parameters([param])
            result = self._set_parameters_atomically(
                [param], descriptors, allow_not_set_type=allow_undeclared_parameters
            )
            if raise_on_failure and not result.successful:
                if result.reason.startswith('Wrong parameter type'):
                    assert descriptors is not None
                    raise InvalidParameterTypeException(param, Parameter.Type(descriptors[param._name].type).name)
                raise InvalidParameterValueException(param.name, param.value, result.reason)
            results.append(result)
        return results

    def set_parameters_atomically(self, parameter_list: list[Parameter]) -> Any:
        self._check_undeclared_parameters(parameter_list)
        return self._set_parameters_atomically(parameter_list)

    def _check_undeclared_parameters(self, parameter_list: list[Parameter]) -> None:
        if not all(isinstance(p, Parameter) for p in parameter_list):
            raise TypeError(f"parameter must be instance of type '{Parameter!r}'")
        undeclared = [p.name for p in parameter_list if p.name not in self._parameters]
        if not self._allow_undeclared_parameters and undeclared:
            raise ParameterNotDeclaredException(undeclared)

    def _set_parameters_atomically(
        self,
        parameter_list: list[Parameter],
        descriptors: dict[str, Any] | None = None,
        allow_not_set_type: bool = False,
    ) -> Any:
        if descriptors is not None:
            result = self._apply_descriptors(parameter_list, descriptors, False)
        else:
            result = self._apply_descriptors(parameter_list, self._descriptors, True)
        if not result.successful:
            return result
        for callback in self._parameters_callbacks:
            result = callback(parameter_list)
            if not result.successful:
                return result
        result = SetParametersResult(successful=True)

        event = ParameterEvent()
        event.node = self._fqn
        for param in parameter_list:
            if not allow_not_set_type and Parameter.Type.NOT_SET == param.type_:
                event.deleted_parameters.append(param.to_parameter_msg())
                self._parameters.pop(param.name, None)
                self._descriptors.pop(param.name, None)
            else:
                if descriptors is not None:
                    self._descriptors[param.name] = descriptors[param.name]
                elif param.name not in self._descriptors:
                    d = ParameterDescriptor()
                    d.dynamic_typing = True
                    self._descriptors[param.name] = d
                if Parameter.Type.NOT_SET == self.get_parameter_or(param.name).type_:
                    event.new_parameters.append(param.to_parameter_msg())
                else:
                    event.changed_parameters.append(param.to_parameter_msg())
                self._parameters[param.name] = param
        event.stamp = self._clock.now().to_msg()
        self._parameter_event_publisher.publish(event)
        return result

    def add_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        self._parameters_callbacks.insert(0, callback)

    def remove_on_set_parameters_callback(self, callback: Callable[[list[Parameter]], Any]) -> None:
        self._parameters_callbacks.remove(callback)

    def _apply_descriptors(
        self, parameter_list: list[Parameter], descriptors: dict[str, Any], check_read_only: bool = True
    ) -> Any:
        for param in parameter_list:
            if param.name in descriptors:
                result = self._apply_descriptor(param, descriptors[param.name], check_read_only)
                if not result.successful:
                    return result
        return SetParametersResult(successful=True)

    def _apply_descriptor(self, parameter: Parameter, descriptor: Any = None, check_read_only: bool = True) -> Any:
        if descriptor is None:
            descriptor = self.describe_parameter(parameter.name)
        else:
            descriptor.name = parameter.name
        if check_read_only and descriptor.read_only:
            return SetParametersResult(
                successful=False, reason=f'Trying to set a read-only parameter: {parameter.name}.'
            )
        if descriptor.dynamic_typing:
            descriptor.type = parameter.type_.value
        elif self.has_parameter(parameter.name) and parameter.type_ == Parameter.Type.NOT_SET:
            return SetParametersResult(successful=False, reason='Static parameter cannot be undeclared')
        elif parameter.type_ != Parameter.Type.NOT_SET and parameter.type_.value != descriptor.type:
            return SetParametersResult(
                successful=False,
                reason=(f"Wrong parameter type, expected '{Parameter.Type(descriptor.type)}' got '{parameter.type_}'"),
            )
        if parameter.type_ == Parameter.Type.INTEGER and descriptor.integer_range:
            return self._apply_integer_range(parameter, descriptor.integer_range[0])
        if parameter.type_ == Parameter.Type.DOUBLE and descriptor.floating_point_range:
            return self._apply_floating_point_range(parameter, descriptor.floating_point_range[0])
        return SetParametersResult(successful=True)

    def _apply_integer_range(self, parameter: Parameter, integer_range: Any) -> Any:
        lo = min(integer_range.from_value, integer_range.to_value)
        hi = max(integer_range.from_value, integer_range.to_value)
        v = parameter.value
        if v == lo or v == hi:
            return SetParametersResult(successful=True)
        if not lo < v < hi:
            return SetParametersResult(
                successful=False, reason=f'Parameter {parameter.name} out of range. Min: {lo}, Max: {hi}, value: {v}'
            )
        if integer_range.step != 0 and (v - lo) % integer_range.step != 0:
            return SetParametersResult(
                successful=False,
                reason=f'The parameter value for {parameter.name} is not a valid step. '
                f'Min: {lo}, max: {hi}, value: {v}, step: {integer_range.step}',
            )
        return SetParametersResult(successful=True)

    def _apply_floating_point_range(self, parameter: Parameter, fp_range: Any) -> Any:
        lo = min(fp_range.from_value, fp_range.to_value)
        hi = max(fp_range.from_value, fp_range.to_value)
        v = parameter.value
        tol = self.PARAM_REL_TOL
        if math.isclose(v, lo, rel_tol=tol) or math.isclose(v, hi, rel_tol=tol):
            return SetParametersResult(successful=True)
        if not lo < v < hi:
            return SetParametersResult(
                successful=False, reason=f'Parameter {parameter.name} out of range Min: {lo}, Max: {hi}, value: {v}'
            )
        if fp_range.step != 0.0:
            steps = round((v - lo) / fp_range.step)
            if not math.isclose(lo + steps * fp_range.step, v, rel_tol=tol):
                return SetParametersResult(
                    successful=False,
                    reason=f'The parameter value for {parameter.name} is not close enough to a '
                    f'valid step. Min: {lo}, max: {hi}, value: {v}, step: {fp_range.step}',
                )
        return SetParametersResult(successful=True)

    def describe_parameter(self, name: str) -> Any:
        try:
            return self._descriptors[name]
        except KeyError:
            if self._allow_undeclared_parameters:
                return ParameterDescriptor()
            raise ParameterNotDeclaredException(name) from None

    def describe_parameters(self, names: list[str]) -> list[Any]:
        return [self.describe_parameter(n) for n in names]

    def set_descriptor(self, name: str, descriptor: Any, alternative_value: Any = None) -> Any:
        if not self.has_parameter(name):
            if not self._allow_undeclared_parameters:
                raise ParameterNotDeclaredException(name)
            return self.get_parameter(name).get_parameter_value()
        if self.describe_parameter(name).read_only:
            raise ParameterImmutableException(name)
        current = self.get_parameter(name)
        alternative = (
            current
            if alternative_value is None
            else Parameter.from_parameter_msg(ParameterMsg(name=name, value=alternative_value))
        )
        if not self._apply_descriptor(current, descriptor, False).successful:
            res = self._apply_descriptor(alternative, descriptor, False)
            if not res.successful:
                raise InvalidParameterValueException(name, alternative.value, res.reason)
            self._parameters[name] = alternative
        self._descriptors[name] = descriptor
        return self.get_parameter(name).get_parameter_value()

    # -- names -------------------------------------------------------------
    def resolve_topic_name(self, topic: str, *, only_expand: bool = False) -> str:
        expanded = expand_topic_name(topic, self._node_name, self._namespace)
        if only_expand:
            return expanded
        for src in reversed(self._arg_sources):  # local rules first
            for rule in src.remaps:
                if rule.src.startswith('__') or rule.node not in (None, self._node_name):
                    continue
                if expand_topic_name(rule.src, self._node_name, self._namespace) == expanded:
                    return expand_topic_name(rule.dst, self._node_name, self._namespace)
        return expanded

    def resolve_service_name(self, service: str, *, only_expand: bool = False) -> str:
        return self.resolve_topic_name(service, only_expand=only_expand)

    @staticmethod
    def _validate_qos_or_depth_parameter(qos_or_depth: QoSProfile | int) -> QoSProfile:
        if isinstance(qos_or_depth, QoSProfile):
            return qos_or_depth
        if isinstance(qos_or_depth, int) and not isinstance(qos_or_depth, bool):
            if qos_or_depth < 0:
                raise ValueError('history depth must be greater than or equal to zero')
            return QoSProfile(depth=qos_or_depth)
        raise TypeError(f'Expected QoSProfile or int, but received {type(qos_or_depth)!r}')

    @staticmethod
    def _check_msg_type(msg_type: Any) -> None:
        if not is_message_class(msg_type):
            raise TypeError(
                f'{msg_type!r} is not a message type of the embedded runtime '
                '(import it from <pkg>.msg after sma_wrist.runtime.activate())'
            )

    # -- entities ----------------------------------------------------------
    def create_publisher(
        self,
        msg_type: Any,
        topic: str,
        qos_profile: QoSProfile | int,
        *,
        callback_group: CallbackGroup | None = None,
        event_callbacks: Any = None,
        qos_overriding_options: Any = None,
        publisher_class: Any = None,
    ) -> Publisher:
        qos = self._validate_qos_or_depth_parameter(qos_profile)
        self._check_msg_type(msg_type)
        name = self.resolve_topic_name(topic)
        graph = self._context.graph
        pub = Publisher(self, msg_type, name, qos, graph.topic(name, msg_type))
        graph.add_publisher(pub)
        self._publishers.append(pub)
        self._wake_executor()
        return pub

    def create_subscription(
        self,
        msg_type: Any,
        topic: str,
        callback: Callable[[Any], None],
        qos_profile: QoSProfile | int,
        *,
        callback_group: CallbackGroup | None = None,
        event_callbacks: Any = None,
        qos_overriding_options: Any = None,
        raw: bool = False,
    ) -> Subscription:
        qos = self._validate_qos_or_depth_parameter(qos_profile)
        self._check_msg_type(msg_type)
        if raw:
            raise NotImplementedError('raw subscriptions are not supported by the embedded runtime')
        name = self.resolve_topic_name(topic)
        graph = self._context.graph
        group = callback_group or self._default_callback_group
        sub = Subscription(self, msg_type, name, callback, group, qos, raw, graph.topic(name, msg_type))
        group.add_entity(sub)
        self._subscriptions.append(sub)
        graph.add_subscription(sub)
        self._wake_executor()
        return sub

    def create_timer(
        self,
        timer_period_sec: float,
        callback: Callable[[], Any],
        callback_group: CallbackGroup | None = None,
        clock: Clock | None = None,
    ) -> Timer:
        period_ns = int(float(timer_period_sec) * S_TO_NS)
        group = callback_group or self._default_callback_group
        timer = Timer(callback, group, period_ns, clock if clock is not None else self._clock, context=self._context)
        group.add_entity(timer)
        self._timers.append(timer)
        self._wake_executor()
        return timer

    def create_client(self, *args: Any, **kwargs: Any) -> Any:
        raise NotImplementedError('services are not part of the embedded runtime subset')

    def create_service(self, *args: Any, **kwargs: Any) -> Any:
        raise NotImplementedError('services are not part of the embedded runtime subset')

    def destroy_publisher(self, publisher: Publisher) -> bool:
        if publisher in self._publishers:
            self._publishers.remove(publisher)
            publisher._destroyed = True
            self._context.graph.remove_publisher(publisher)
            self._wake_executor()
            return True
        return False

    def destroy_subscription(self, subscription: Subscription) -> bool:
        if subscription in self._subscriptions:
            self._subscriptions.remove(subscription)
            self._context.graph.remove_subscription(subscription)
            subscription._queue.clear()
            self._wake_executor()
            return True
        return False

    def destroy_timer(self, timer: Timer) -> bool:
        if timer in self._timers:
            self._timers.remove(timer)
            timer.destroy()
            self._wake_executor()
            return True
        return False

    def destroy_node(self) -> None:
        if self._destroyed:
            return
        for pub in list(self._publishers):
            self.destroy_publisher(pub)
        for sub in list(self._subscriptions):
            self.destroy_subscription(sub)
        for tmr in list(self._timers):
            self.destroy_timer(tmr)
        if self._executor is not None:
            self._executor.remove_node(self)
        nodes = self._context.graph.nodes
        if self in nodes:
            nodes.remove(self)
        self._destroyed = True

    # -- graph introspection -----------------------------------------------
    def count_publishers(self, topic_name: str) -> int:
        name = expand_topic_name(topic_name, self._node_name, self._namespace)
        t = self._context.graph.topics.get(name)
        return len(t.publishers) if t else 0

    def count_subscribers(self, topic_name: str) -> int:
        name = expand_topic_name(topic_name, self._node_name, self._namespace)
        t = self._context.graph.topics.get(name)
        return len(t.subscriptions) if t else 0

    def get_topic_names_and_types(self, no_demangle: bool = False) -> list[tuple[str, list[str]]]:
        return sorted(
            (t.name, [t.msg_type._TYPE]) for t in self._context.graph.topics.values() if t.publishers or t.subscriptions
        )

    def get_node_names(self) -> list[str]:
        return [n.get_name() for n in self._context.graph.nodes]

    def get_node_names_and_namespaces(self) -> list[tuple[str, str]]:
        return [(n.get_name(), n.get_namespace()) for n in self._context.graph.nodes]

    def __repr__(self) -> str:
        return f'<embedded Node {self._fqn}>'
