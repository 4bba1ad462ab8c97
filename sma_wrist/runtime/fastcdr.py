"""Direct CDR (little endian) for the graph's high-rate message types.

A closed-loop run records ~15 messages per 10 ms control tick, most of them
``std_msgs/Float64``, ``sensor_msgs/Temperature``, ``sensor_msgs/JointState`` and
``rosgraph_msgs/Clock``. Going through rosbags' typestore costs a conversion to its
dataclass plus its generic serialiser (2-10 us a message, the bulk of a recorded run's
overhead); these four layouts are packed and unpacked here with ``struct`` directly, from
and to the runtime's message objects. Every other type goes through the typestore.

The bytes are those of rosbags' serialiser (CDR_LE encapsulation header ``00 01 00 00``,
alignment counted from after the header, no alignment before the elements of an empty
sequence); test_bag checks them byte for byte against ``TYPESTORE.serialize_cdr`` and the
decoders against ``TYPESTORE.deserialize_cdr``.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

from .messages import TYPESTORE, get_message_class

Encoder = Callable[[Any], bytes]
Decoder = Callable[[bytes], Any]

_HEADER = b'\x00\x01\x00\x00'  # CDR little endian, options 0
_F64 = struct.Struct('<4sd')
_STAMP_LEN = struct.Struct('<iII')  # sec, nanosec, string length (incl. NUL)
_U32 = struct.Struct('<I')
_D = struct.Struct('<d')
_DD = struct.Struct('<dd')
_CLOCK = struct.Struct('<4siI')
_ZEROS = bytes(8)
_DOUBLES: dict[int, struct.Struct] = {}  # '<nd' by n: sequences have a handful of lengths


def _pad(pos: int, align: int) -> int:
    return -pos % align


# ------------------------------------------------------------------------------- encoders
def _header_parts(h: Any, parts: list[bytes]) -> int:
    """Append std_msgs/Header; return the position after it (relative to the CDR body)."""
    fid = h.frame_id.encode()
    parts.append(_STAMP_LEN.pack(h.stamp.sec, h.stamp.nanosec, len(fid) + 1))
    parts.append(fid)
    parts.append(b'\x00')
    return 13 + len(fid)


def _float64(msg: Any) -> bytes:
    return _F64.pack(_HEADER, msg.data)


def _clock(msg: Any) -> bytes:
    return _CLOCK.pack(_HEADER, msg.clock.sec, msg.clock.nanosec)


def _temperature(msg: Any) -> bytes:
    parts = [_HEADER]
    pos = _header_parts(msg.header, parts)
    parts.append(_ZEROS[: _pad(pos, 8)])
    parts.append(_DD.pack(msg.temperature, msg.variance))
    return b''.join(parts)


def _float_seq(seq: Any, pos: int, parts: list[bytes]) -> int:
    pad = _pad(pos, 4)
    n = len(seq)
    parts.append(_ZEROS[:pad])
    parts.append(_U32.pack(n))
    pos += pad + 4
    if n:
        pad = _pad(pos, 8)
        parts.append(_ZEROS[:pad])
        parts.append(struct.pack(f'<{n}d', *seq))
        pos += pad + 8 * n
    return pos


def _joint_state(msg: Any) -> bytes:
    parts = [_HEADER]
    pos = _header_parts(msg.header, parts)
    pad = _pad(pos, 4)
    parts.append(_ZEROS[:pad])
    parts.append(_U32.pack(len(msg.name)))
    pos += pad + 4
    for name in msg.name:
        b = name.encode()
        pad = _pad(pos, 4)
        parts.append(_ZEROS[:pad])
        parts.append(_U32.pack(len(b) + 1))
        parts.append(b)
        parts.append(b'\x00')
        pos += pad + 5 + len(b)
    for seq in (msg.position, msg.velocity, msg.effort):
        pos = _float_seq(seq, pos, parts)
    return b''.join(parts)


# ------------------------------------------------------------------------------- decoders
# decoded messages are built with object.__new__ and every field assigned: __init__'s
# keyword checks and defaults cost more than the unpacking
_new = object.__new__


def _read_header(data: bytes, pos: int, Header: Any, Time: Any) -> tuple[Any, int]:
    sec, nanosec, n = _STAMP_LEN.unpack_from(data, pos)
    end = pos + 12 + n
    if n < 1 or end > len(data):
        raise ValueError('frame_id runs past the end of the message')
    stamp = _new(Time)
    stamp.sec, stamp.nanosec = sec, nanosec
    h = _new(Header)
    h.stamp, h.frame_id = stamp, data[pos + 12 : end - 1].decode()
    return h, end


def _decoders() -> dict[str, Decoder]:
    Float64 = get_message_class('std_msgs/msg/Float64')
    Temperature = get_message_class('sensor_msgs/msg/Temperature')
    JointState = get_message_class('sensor_msgs/msg/JointState')
    Clock = get_message_class('rosgraph_msgs/msg/Clock')
    Header = get_message_class('std_msgs/msg/Header')
    Time = get_message_class('builtin_interfaces/msg/Time')

    def float64(data: bytes) -> Any:
        o = _new(Float64)
        o.data = _F64.unpack_from(data)[1]
        return o

    def clock(data: bytes) -> Any:
        o, t = _new(Clock), _new(Time)
        _, t.sec, t.nanosec = _CLOCK.unpack_from(data)
        o.clock = t
        return o

    def temperature(data: bytes) -> Any:
        header, pos = _read_header(data, 4, Header, Time)
        pos += _pad(pos - 4, 8)
        o = _new(Temperature)
        o.header = header
        o.temperature, o.variance = _DD.unpack_from(data, pos)
        return o

    def floats(data: bytes, pos: int) -> tuple[list[float], int]:
        pos += _pad(pos - 4, 4)
        (n,) = _U32.unpack_from(data, pos)
        pos += 4
        if not n:
            return [], pos
        pos += _pad(pos - 4, 8)
        if pos + 8 * n > len(data):
            raise ValueError('sequence runs past the end of the message')
        packer = _DOUBLES.get(n)
        if packer is None:
            packer = _DOUBLES[n] = struct.Struct(f'<{n}d')
        return list(packer.unpack_from(data, pos)), pos + 8 * n

    def joint_state(data: bytes) -> Any:
        header, pos = _read_header(data, 4, Header, Time)
        pos += _pad(pos - 4, 4)
        (count,) = _U32.unpack_from(data, pos)
        pos += 4
        if count > len(data):
            raise ValueError('name sequence longer than the message')
        names = []
        for _ in range(count):
            pos += _pad(pos - 4, 4)
            (n,) = _U32.unpack_from(data, pos)
            if n < 1 or pos + 4 + n > len(data):
                raise ValueError('name runs past the end of the message')
            names.append(data[pos + 4 : pos + 3 + n].decode())
            pos += 4 + n
        position, pos = floats(data, pos)
        velocity, pos = floats(data, pos)
        effort, pos = floats(data, pos)
        o = _new(JointState)
        o.header, o.name, o.position, o.velocity, o.effort = header, names, position, velocity, effort
        return o

    return {
        'std_msgs/msg/Float64': float64,
        'rosgraph_msgs/msg/Clock': clock,
        'sensor_msgs/msg/Temperature': temperature,
        'sensor_msgs/msg/JointState': joint_state,
    }


_ENCODERS: dict[str, Encoder] = {
    'std_msgs/msg/Float64': _float64,
    'rosgraph_msgs/msg/Clock': _clock,
    'sensor_msgs/msg/Temperature': _temperature,
    'sensor_msgs/msg/JointState': _joint_state,
}
_DECODERS: dict[str, Decoder] = {}


def encoder_for(typename: str) -> Encoder:
    """``msg -> CDR bytes`` for a message type: a direct packer for the high-rate types, the
    typestore for the rest."""
    fast = _ENCODERS.get(typename)
    if fast is not None:
        return fast

    def generic(msg: Any) -> bytes:
        return TYPESTORE.serialize_cdr(msg._to_rb(), typename)

    return generic


def decoder_for(typename: str) -> Decoder:
    """``CDR bytes -> message`` (runtime message classes); raises on bytes that do not hold one."""
    if not _DECODERS:
        _DECODERS.update(_decoders())
    fast = _DECODERS.get(typename)
    if fast is not None:

        def checked(data: bytes, _fast: Decoder = fast) -> Any:
            if data[:4] != _HEADER:
                # big-endian or unusual encapsulation (another recorder): the typestore handles it
                return get_message_class(typename)._from_rb(TYPESTORE.deserialize_cdr(data, typename))
            return _fast(data)

        return checked
    cls = get_message_class(typename)

    def generic(data: bytes) -> Any:
        return cls._from_rb(TYPESTORE.deserialize_cdr(data, typename))

    return generic


__all__ = ['encoder_for', 'decoder_for']
