"""Exceptions with the names, bases and messages of rclpy/exceptions.py (Humble)."""

from __future__ import annotations

from typing import Any


class NotInitializedException(Exception):
    """Raised when the rclpy implementation is accessed before rclpy.init()."""

    def __init__(self, *args: Any) -> None:
        Exception.__init__(self, 'rclpy.init() has not been called', *args)


class NoTypeSupportImportedException(Exception):
    def __init__(self, *args: Any) -> None:
        Exception.__init__(self, 'no type_support imported', *args)


class NameValidationException(Exception):
    def __init__(self, name_type: str, name: str, error_msg: str, invalid_index: int) -> None:
        self.name = name
        self.error_msg = error_msg
        self.invalid_index = invalid_index
        Exception.__init__(self, f'Invalid {name_type}: {error_msg}:\n  {name}\n  {" " * invalid_index}^')


class InvalidNamespaceException(NameValidationException):
    def __init__(self, name: str, error_msg: str, invalid_index: int) -> None:
        NameValidationException.__init__(self, 'namespace', name, error_msg, invalid_index)


class InvalidNodeNameException(NameValidationException):
    def __init__(self, name: str, error_msg: str, invalid_index: int) -> None:
        NameValidationException.__init__(self, 'node name', name, error_msg, invalid_index)


class InvalidTopicNameException(NameValidationException):
    def __init__(self, name: str, error_msg: str, invalid_index: int) -> None:
        NameValidationException.__init__(self, 'topic name', name, error_msg, invalid_index)


class InvalidServiceNameException(NameValidationException):
    def __init__(self, name: str, error_msg: str, invalid_index: int) -> None:
        NameValidationException.__init__(self, 'service name', name, error_msg, invalid_index)


class ParameterException(Exception):
    """Base exception for parameter-related errors."""

    def __init__(self, error_msg: str, parameters: Any, *args: Any) -> None:
        Exception.__init__(self, f'{error_msg}: {parameters}')


class ParameterNotDeclaredException(ParameterException):
    def __init__(self, parameters: Any, *args: Any) -> None:
        ParameterException.__init__(self, 'Invalid access to undeclared parameter(s)', parameters, *args)


class ParameterAlreadyDeclaredException(ParameterException):
    def __init__(self, parameters: Any, *args: Any) -> None:
        ParameterException.__init__(self, 'Parameter(s) already declared', parameters, *args)


class InvalidParameterException(ParameterException):
    def __init__(self, parameter: Any, *args: Any) -> None:
        ParameterException.__init__(self, 'Invalid parameter name', parameter, *args)


class InvalidParameterTypeException(ParameterException):
    def __init__(self, desired_parameter: Any, expected_type: str, *args: Any) -> None:
        Exception.__init__(
            self,
            f"Trying to set parameter '{desired_parameter._name}' to '{desired_parameter._value}'"
            f" of type '{desired_parameter._type_.name}', expecting type '{expected_type}'",
            *args,
        )  # Humble: the message alone (no parameter name appended)


class InvalidParameterValueException(ParameterException):
    def __init__(self, parameter: Any, value: Any, reason: str, *args: Any) -> None:
        Exception.__init__(self, f'Invalid parameter value ({value}) for parameter. Reason: {reason}', parameter, *args)


class ParameterImmutableException(ParameterException):
    def __init__(self, parameters: Any, *args: Any) -> None:
        ParameterException.__init__(self, 'Attempted to modify read-only parameter', parameters, *args)


class ParameterUninitializedException(ParameterException):
    def __init__(self, parameter_name: str, *args: Any) -> None:
        Exception.__init__(self, f"The parameter '{parameter_name}' is not initialized", *args)


class ROSInterruptException(Exception):
    def __init__(self, *args: Any) -> None:
        Exception.__init__(self, 'rclpy.shutdown() has been called', *args)


class InvalidHandle(Exception):
    def __init__(self, *args: Any) -> None:
        Exception.__init__(self, *args)


class RCLError(RuntimeError):
    """rcl's error (``rclpy._rclpy_pybind11.RCLError`` in rclpy), e.g. publishing after the context shut down."""
