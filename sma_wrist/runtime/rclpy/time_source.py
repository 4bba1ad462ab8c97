"""TimeSource: use_sim_time handling as in rclpy/time_source.py (Humble).

Declares ``use_sim_time`` (False) if the node has not, activates the ROS time override of
attached clocks when it is true, and then subscribes to /clock with
``QoSProfile(depth=1, reliability=BEST_EFFORT)``; each Clock message sets the override.
"""

from __future__ import annotations

import weakref
from typing import Any

from sma_wrist.runtime.messages import get_message_class

from .clock import ROSClock
from .clock_type import ClockType
from .parameter import Parameter
from .qos import QoSProfile, ReliabilityPolicy
from .time import Time

CLOCK_TOPIC = '/clock'
USE_SIM_TIME_NAME = 'use_sim_time'


class TimeSource:
    def __init__(self, *, node: Any = None) -> None:
        self._clock_sub: Any = None
        self._node_weak_ref: weakref.ref[Any] | None = None
        self._associated_clocks: list[ROSClock] = []
        self._last_time_set = Time(clock_type=ClockType.ROS_TIME)
        self._ros_time_is_active = False
        if node is not None:
            self.attach_node(node)

    @property
    def ros_time_is_active(self) -> bool:
        return self._ros_time_is_active

    @ros_time_is_active.setter
    def ros_time_is_active(self, enabled: bool) -> None:
        if self._ros_time_is_active == enabled:
            return
        self._ros_time_is_active = enabled
        for clock in self._associated_clocks:
            clock._set_ros_time_is_active(enabled)
        if enabled:
            self._subscribe_to_clock_topic()
        elif self._clock_sub is not None:
            node = self._get_node()
            if node is not None:
                node.destroy_subscription(self._clock_sub)
                self._clock_sub = None

    def _subscribe_to_clock_topic(self) -> None:
        if self._clock_sub is None:
            node = self._get_node()
            if node is not None:
                self._clock_sub = node.create_subscription(
                    get_message_class('rosgraph_msgs/msg/Clock'),
                    CLOCK_TOPIC,
                    self.clock_callback,
                    QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT),
                )

    def attach_node(self, node: Any) -> None:
        from .node import Node

        if not isinstance(node, Node):
            raise TypeError('Node must be of type rclpy.node.Node')
        if self._node_weak_ref is not None:
            self.detach_node()
        self._node_weak_ref = weakref.ref(node)
        if not node.has_parameter(USE_SIM_TIME_NAME):
            node.declare_parameter(USE_SIM_TIME_NAME, False)
        param = node.get_parameter(USE_SIM_TIME_NAME)
        if param.type_ != Parameter.Type.NOT_SET:
            if param.type_ == Parameter.Type.BOOL:
                self.ros_time_is_active = param.value
            else:
                node.get_logger().error(
                    f"Invalid type for parameter '{USE_SIM_TIME_NAME}' {param.type_!r} should be bool"
                )
        node.add_on_set_parameters_callback(self._on_parameter_event)

    def detach_node(self) -> None:
        if self._clock_sub is not None:
            node = self._get_node()
            if node is None:
                raise RuntimeError('Unable to destroy previously created clock subscription')
            node.destroy_subscription(self._clock_sub)
        self._clock_sub = None
        self._node_weak_ref = None

    def attach_clock(self, clock: ROSClock) -> None:
        if not isinstance(clock, ROSClock):
            raise ValueError('Only clocks with type ROS_TIME can be attached.')
        clock.set_ros_time_override(self._last_time_set)
        clock._set_ros_time_is_active(self.ros_time_is_active)
        self._associated_clocks.append(clock)

    def clock_callback(self, msg: Any) -> None:
        ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        self._last_time_set = Time._from_ns(ns, ClockType.ROS_TIME)
        for clock in self._associated_clocks:
            clock._set_override_ns(ns)

    def _on_parameter_event(self, parameter_list: list[Parameter]) -> Any:
        for parameter in parameter_list:
            if parameter.name == USE_SIM_TIME_NAME:
                if parameter.type_ == Parameter.Type.BOOL:
                    self.ros_time_is_active = parameter.value
                else:
                    node = self._get_node()
                    if node:
                        node.get_logger().error(f'{USE_SIM_TIME_NAME} parameter set to something besides a bool')
                break
        return get_message_class('rcl_interfaces/msg/SetParametersResult')(successful=True)

    def _get_node(self) -> Any:
        return self._node_weak_ref() if self._node_weak_ref is not None else None
