"""rclpy-like message classes generated from rosbags' typestore (ROS 2 Humble definitions).

A generated class behaves like a rosidl-generated Python message for the parts node code
uses: default construction (nested messages and ``builtin_interfaces/Time`` defaulted),
keyword construction (unknown keywords rejected like rosidl's ``__init__`` assertion),
attribute assignment, constants as class attributes (``byte`` constants are ``bytes`` as
in rosidl), equality, ``__repr__`` (``std_msgs.msg.Float64(data=1.0)``) and
``get_fields_and_field_types()``.

Differences from rosidl (documented in doc/explanation/runtime.md): sequences and fixed arrays are
plain Python lists (rosidl uses ``array.array`` / numpy), and assignment is not type
checked.

Conversion to and from rosbags' dataclasses (``to_rosbags`` / ``from_rosbags``) gives CDR
serialisation through ``TYPESTORE.serialize_cdr``; the converters, a fast ``_copy`` (used
to give each subscription its own message, as a middleware round trip would) and
``__init__`` are generated once per type and cached.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from .errors import MessageTypeError

TYPESTORE: Typestore = get_typestore(Stores.ROS2_HUMBLE)

BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4

_NUMPY_DTYPES: dict[str, Any] = {
    'bool': np.bool_,
    'byte': np.uint8,
    'char': np.uint8,
    'int8': np.int8,
    'uint8': np.uint8,
    'int16': np.int16,
    'uint16': np.uint16,
    'int32': np.int32,
    'uint32': np.uint32,
    'int64': np.int64,
    'uint64': np.uint64,
    'float32': np.float32,
    'float64': np.float64,
}
_DEFAULTS: dict[str, Any] = {
    'bool': False,
    'byte': b'\x00',
    'char': 0,
    'string': '',
    'wstring': '',
    'float32': 0.0,
    'float64': 0.0,
}

_CLASSES: dict[str, type[Message]] = {}
_MODULES: dict[str, types.ModuleType] = {}


class Message:
    """Base of every generated message class."""

    __slots__ = ()
    _TYPE: ClassVar[str] = ''
    _FIELDS: ClassVar[tuple[str, ...]] = ()
    _FIELD_TYPES: ClassVar[dict[str, str]] = {}
    _copy: Callable[[Message], Message]
    _to_rb: Callable[[Message], Any]
    _from_rb: ClassVar[Callable[[Any], Message]]

    @classmethod
    def get_fields_and_field_types(cls) -> dict[str, str]:
        return dict(cls._FIELD_TYPES)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return False
        for name in self._FIELDS:
            a, b = getattr(self, name), getattr(other, name)
            if isinstance(a, (list, tuple, np.ndarray)) or isinstance(b, (list, tuple, np.ndarray)):
                if len(a) != len(b) or any(x != y for x, y in zip(a, b)):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]  # mutable, like rosidl messages

    def __repr__(self) -> str:
        pkg, _, name = self._TYPE.split('/')
        args = ', '.join(f'{f}={getattr(self, f)!r}' for f in self._FIELDS)
        return f'{pkg}.msg.{name}({args})'


def _type_str(node: tuple[Any, Any]) -> str:
    kind, arg = node
    if kind == BASE:
        base, bound = arg
        return f'{base}<={bound}' if bound else base
    if kind == NAME:
        pkg, _, name = arg.split('/')
        return f'{pkg}/{name}'
    sub, n = arg
    if kind == ARRAY:
        return f'{_type_str(sub)}[{n}]'
    return f'sequence<{_type_str(sub)}, {n}>' if n else f'sequence<{_type_str(sub)}>'


def _scalar_default(node: tuple[Any, Any], ns: dict[str, Any]) -> str:
    """Source expression of a fresh default value for one field."""
    kind, arg = node
    if kind == BASE:
        base = arg[0]
        if base in _DEFAULTS:
            return repr(_DEFAULTS[base])
        return '0'
    if kind == NAME:
        cname = _ident(arg)
        ns[cname] = get_message_class(arg)
        return f'{cname}()'
    sub, n = arg
    if kind == ARRAY:
        return f'[{_scalar_default(sub, ns)} for _ in range({n})]'
    return '[]'


def _ident(typename: str) -> str:
    return '_' + typename.replace('/', '__')


def _build_class(typename: str) -> type[Message]:
    try:
        consts, fields = TYPESTORE.fielddefs[typename]
    except KeyError:
        raise MessageTypeError(f'message type {typename!r} is not in the ROS 2 Humble typestore') from None
    rbcls = TYPESTORE.types[typename]
    pkg, _, name = typename.split('/')
    names = tuple(f for f, _ in fields)
    ns: dict[str, Any] = {'np': np, '_RB': rbcls, '_valid': frozenset(names)}

    init = [
        'def __init__(self, **kw):',
        '    if kw and not _valid.issuperset(kw):',
        "        raise AssertionError('Invalid arguments passed to constructor: %s' % "
        "', '.join(sorted(set(kw) - _valid)))",
    ]
    copy = ['def _copy(self):', '    o = _new(_cls)']
    to_rb = ['def _to_rb(self):', '    return _RB(']
    from_rb = ['def _from_rb(m):', '    o = _new(_cls)']
    for fname, node in fields:
        kind, arg = node
        default = _scalar_default(node, ns)
        if kind in (ARRAY, SEQUENCE):
            sub = arg[0]
            init.append(f"    self.{fname} = list(kw['{fname}']) if '{fname}' in kw else {default}")
            if sub[0] == NAME:
                copy.append(f'    o.{fname} = [x._copy() for x in self.{fname}]')
                to_rb.append(f'        {fname}=[x._to_rb() for x in self.{fname}],')
                cname = _ident(sub[1])
                ns[cname] = get_message_class(sub[1])
                from_rb.append(f'    o.{fname} = [{cname}._from_rb(x) for x in m.{fname}]')
            elif sub[1][0] in ('string', 'wstring'):
                copy.append(f'    o.{fname} = list(self.{fname})')
                to_rb.append(f'        {fname}=list(self.{fname}),')
                from_rb.append(f'    o.{fname} = list(m.{fname})')
            else:
                base = sub[1][0]
                ns[f'_dt_{fname}'] = _NUMPY_DTYPES[base]
                copy.append(f'    o.{fname} = list(self.{fname})')
                if base == 'byte':
                    to_rb.append(
                        f'        {fname}=np.frombuffer(b"".join(x if isinstance(x, bytes) '
                        f'else bytes((x,)) for x in self.{fname}), dtype=np.uint8),'
                    )
                    from_rb.append(f'    o.{fname} = [bytes((x,)) for x in m.{fname}.tolist()]')
                else:
                    to_rb.append(f'        {fname}=np.asarray(self.{fname}, dtype=_dt_{fname}),')
                    from_rb.append(f'    o.{fname} = m.{fname}.tolist()')
        elif kind == NAME:
            init.append(f"    self.{fname} = kw['{fname}'] if '{fname}' in kw else {default}")
            copy.append(f'    o.{fname} = self.{fname}._copy()')
            to_rb.append(f'        {fname}=self.{fname}._to_rb(),')
            cname = _ident(arg)
            from_rb.append(f'    o.{fname} = {cname}._from_rb(m.{fname})')
        else:
            init.append(f"    self.{fname} = kw.get('{fname}', {default})")
            copy.append(f'    o.{fname} = self.{fname}')
            if arg[0] == 'byte':
                to_rb.append(
                    f'        {fname}=self.{fname}[0] if isinstance(self.{fname}, bytes) else int(self.{fname}),'
                )
                from_rb.append(f'    o.{fname} = bytes((m.{fname},))')
            elif arg[0] in ('float32', 'float64'):
                to_rb.append(f'        {fname}=float(self.{fname}),')
                from_rb.append(f'    o.{fname} = m.{fname}')
            else:
                to_rb.append(f'        {fname}=self.{fname},')
                from_rb.append(f'    o.{fname} = m.{fname}')
    copy.append('    return o')
    to_rb.append('    )')
    from_rb.append('    return o')
    src = '\n'.join(init + copy + to_rb + from_rb) + '\n'
    code = compile(src, f'<sma_wrist message {typename}>', 'exec')
    exec(code, ns)  # noqa: S102 - generated from typestore field definitions only

    attrs: dict[str, Any] = {
        '__slots__': names,
        '__module__': f'{pkg}.msg',
        '__qualname__': name,
        '_TYPE': typename,
        '_FIELDS': names,
        '_FIELD_TYPES': {f: _type_str(n) for f, n in fields},
        '__init__': ns['__init__'],
        '_copy': ns['_copy'],
        '_to_rb': ns['_to_rb'],
    }
    for cname, ctype, value in consts:
        attrs[cname] = bytes((value,)) if ctype == 'byte' and isinstance(value, int) else value
    cls = type(name, (Message,), attrs)
    ns['_cls'] = cls
    ns['_new'] = object.__new__
    cls._from_rb = staticmethod(ns['_from_rb'])  # type: ignore[assignment]
    return cls


def get_message_class(typename: str) -> type[Message]:
    """Return the cached class for ``pkg/msg/Name`` (``pkg/Name`` accepted)."""
    cls = _CLASSES.get(typename)
    if cls is None:
        parts = typename.split('/')
        if len(parts) == 2:
            typename = f'{parts[0]}/msg/{parts[1]}'
            cls = _CLASSES.get(typename)
        if cls is None:
            cls = _build_class(typename)
            _CLASSES[typename] = cls
    return cls


def is_message_class(obj: object) -> bool:
    return isinstance(obj, type) and issubclass(obj, Message) and obj is not Message


def message_type_name(cls: type) -> str:
    """``std_msgs/msg/Float64`` for a generated class (or a real rclpy class)."""
    if is_message_class(cls):
        return cls._TYPE  # type: ignore[attr-defined]
    mod = getattr(cls, '__module__', '')
    pkg = mod.split('.')[0]
    return f'{pkg}/msg/{cls.__name__}'


def to_rosbags(msg: Message) -> Any:
    return msg._to_rb()


def from_rosbags(obj: Any) -> Message:
    return get_message_class(obj.__msgtype__)._from_rb(obj)


def serialize(msg: Message) -> bytes:
    """CDR bytes of msg (little endian, as rosbag2 stores them)."""
    return bytes(TYPESTORE.serialize_cdr(msg._to_rb(), msg._TYPE))


def deserialize(data: bytes | memoryview, typename: str) -> Message:
    return get_message_class(typename)._from_rb(TYPESTORE.deserialize_cdr(data, typename))


def packages() -> set[str]:
    """Interface packages the typestore knows (``std_msgs``, ``sensor_msgs``, ...)."""
    return {t.split('/')[0] for t in TYPESTORE.fielddefs if t.split('/')[1] == 'msg'}


def _make_msg_module(pkg: str) -> types.ModuleType:
    names = sorted(t.split('/')[2] for t in TYPESTORE.fielddefs if t.startswith(f'{pkg}/msg/'))
    mod = types.ModuleType(f'{pkg}.msg', f'{pkg} messages generated from the ROS 2 Humble typestore')

    def __getattr__(attr: str) -> type[Message]:
        if attr in names:
            cls = get_message_class(f'{pkg}/msg/{attr}')
            setattr(mod, attr, cls)
            return cls
        raise AttributeError(f"module '{pkg}.msg' has no attribute '{attr}'")

    def __dir__() -> list[str]:
        return names

    mod.__getattr__ = __getattr__  # type: ignore[method-assign]
    mod.__dir__ = __dir__  # type: ignore[method-assign]
    mod.__all__ = names  # type: ignore[attr-defined]
    mod.__package__ = pkg
    return mod


def msg_module(pkg: str) -> types.ModuleType:
    """The ``<pkg>.msg`` module (cached; created on first use)."""
    key = f'{pkg}.msg'
    mod = _MODULES.get(key)
    if mod is None:
        if pkg not in packages():
            raise MessageTypeError(f'interface package {pkg!r} is not in the ROS 2 Humble typestore')
        mod = _make_msg_module(pkg)
        _MODULES[key] = mod
    return mod


def package_module(pkg: str) -> types.ModuleType:
    """The ``<pkg>`` package module, whose ``msg`` attribute is ``msg_module(pkg)``."""
    mod = _MODULES.get(pkg)
    if mod is None:
        if pkg not in packages():
            raise MessageTypeError(f'interface package {pkg!r} is not in the ROS 2 Humble typestore')
        mod = types.ModuleType(pkg, f'{pkg} interfaces (embedded, from the rosbags typestore)')
        mod.__path__ = []  # a package, so `import pkg.msg` is resolved by our finder
        mod.__package__ = pkg
        mod.msg = msg_module(pkg)  # type: ignore[attr-defined]
        _MODULES[pkg] = mod
    return mod


def msg(typename: str) -> type[Message]:
    """Short alias of get_message_class for runtime-internal use."""
    return get_message_class(typename)


__all__ = [
    'Message',
    'TYPESTORE',
    'deserialize',
    'from_rosbags',
    'get_message_class',
    'is_message_class',
    'message_type_name',
    'msg_module',
    'package_module',
    'packages',
    'serialize',
    'to_rosbags',
]
