"""rclpy.parameter.Parameter (behaviour of rclpy/parameter.py, Humble)."""

from __future__ import annotations

import array
from enum import Enum
from typing import Any

from sma_wrist.runtime.messages import get_message_class

_ParameterMsg = get_message_class('rcl_interfaces/msg/Parameter')
_ParameterValue = get_message_class('rcl_interfaces/msg/ParameterValue')
_PT = get_message_class('rcl_interfaces/msg/ParameterType')

PARAMETER_SEPARATOR_STRING = '.'

_VALUE_FIELDS = {
    1: 'bool_value',
    2: 'integer_value',
    3: 'double_value',
    4: 'string_value',
    5: 'byte_array_value',
    6: 'bool_array_value',
    7: 'integer_array_value',
    8: 'double_array_value',
    9: 'string_array_value',
}


class Parameter:
    __slots__ = ('_type_', '_name', '_value')

    class Type(Enum):
        NOT_SET = _PT.PARAMETER_NOT_SET
        BOOL = _PT.PARAMETER_BOOL
        INTEGER = _PT.PARAMETER_INTEGER
        DOUBLE = _PT.PARAMETER_DOUBLE
        STRING = _PT.PARAMETER_STRING
        BYTE_ARRAY = _PT.PARAMETER_BYTE_ARRAY
        BOOL_ARRAY = _PT.PARAMETER_BOOL_ARRAY
        INTEGER_ARRAY = _PT.PARAMETER_INTEGER_ARRAY
        DOUBLE_ARRAY = _PT.PARAMETER_DOUBLE_ARRAY
        STRING_ARRAY = _PT.PARAMETER_STRING_ARRAY

        @classmethod
        def from_parameter_value(cls, parameter_value: Any) -> Parameter.Type:
            """Parameter.Type of a Python value; TypeError if there is none."""
            v = parameter_value
            if v is None:
                return cls.NOT_SET
            if isinstance(v, bool):
                return cls.BOOL
            if isinstance(v, int):
                return cls.INTEGER
            if isinstance(v, float):
                return cls.DOUBLE
            if isinstance(v, str):
                return cls.STRING
            if isinstance(v, (list, tuple, array.array)):
                if all(isinstance(x, bytes) for x in v):
                    return cls.BYTE_ARRAY
                if all(isinstance(x, bool) for x in v):
                    return cls.BOOL_ARRAY
                if all(isinstance(x, int) for x in v):
                    return cls.INTEGER_ARRAY
                if all(isinstance(x, float) for x in v):
                    return cls.DOUBLE_ARRAY
                if all(isinstance(x, str) for x in v):
                    return cls.STRING_ARRAY
                raise TypeError(f"The given value is not a list of one of the allowed types '{v}'.")
            raise TypeError(f"The given value is not one of the allowed types '{v}'.")

        def check(self, parameter_value: Any) -> bool:
            T = Parameter.Type
            v = parameter_value
            if self is T.NOT_SET:
                return v is None
            if self is T.BOOL:
                return isinstance(v, bool)
            if self is T.INTEGER:
                return isinstance(v, int)
            if self is T.DOUBLE:
                return isinstance(v, float)
            if self is T.STRING:
                return isinstance(v, str)
            if self is T.BYTE_ARRAY:
                return isinstance(v, (list, tuple)) and all(isinstance(x, bytes) and len(x) == 1 for x in v)
            if self is T.BOOL_ARRAY:
                return isinstance(v, (list, tuple)) and all(isinstance(x, bool) for x in v)
            if self is T.INTEGER_ARRAY:
                return isinstance(v, (list, tuple, array.array)) and all(isinstance(x, int) for x in v)
            if self is T.DOUBLE_ARRAY:
                return isinstance(v, (list, tuple, array.array)) and all(isinstance(x, float) for x in v)
            if self is T.STRING_ARRAY:
                return isinstance(v, (list, tuple)) and all(isinstance(x, str) for x in v)
            return False

    @classmethod
    def from_parameter_msg(cls, param_msg: Any) -> Parameter:
        type_ = Parameter.Type(param_msg.value.type)
        field = _VALUE_FIELDS.get(type_.value)
        value = getattr(param_msg.value, field) if field else None
        return cls(param_msg.name, type_, value)

    def __init__(self, name: str, type_: Parameter.Type | None = None, value: Any = None) -> None:
        if type_ is None:
            type_ = Parameter.Type.from_parameter_value(value)
        if not isinstance(type_, Parameter.Type):
            raise TypeError(f"type must be an instance of '{Parameter.Type!r}'")
        if not type_.check(value):
            raise ValueError(f"Type '{type_}' and value '{value}' do not agree")
        self._type_ = type_
        self._name = name
        self._value = value

    @property
    def name(self) -> str:
        return self._name

    @property
    def type_(self) -> Parameter.Type:
        return self._type_

    @property
    def value(self) -> Any:
        return self._value

    def get_parameter_value(self) -> Any:
        pv = _ParameterValue(type=self._type_.value)
        field = _VALUE_FIELDS.get(self._type_.value)
        if field:
            setattr(
                pv, field, list(self._value) if isinstance(self._value, (list, tuple, array.array)) else self._value
            )
        return pv

    def to_parameter_msg(self) -> Any:
        return _ParameterMsg(name=self._name, value=self.get_parameter_value())

    def __repr__(self) -> str:
        return f'Parameter(name={self._name!r}, type_={self._type_}, value={self._value!r})'


def parameter_value_to_python(parameter_value: Any) -> Any:
    """Python value of an rcl_interfaces/ParameterValue (None for NOT_SET)."""
    t = parameter_value.type
    if t == _PT.PARAMETER_NOT_SET:
        return None
    field = _VALUE_FIELDS.get(t)
    if field is None:
        raise RuntimeError(f'unexpected parameter type {t}')
    value = getattr(parameter_value, field)
    return list(value) if t >= 5 else value
