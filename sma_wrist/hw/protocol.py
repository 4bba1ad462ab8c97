"""The wrist's serial line protocol, version 1 (pure: no ROS, no serial port).

One frame per line, ASCII::

    $<TYPE>,<ver>,<field>,...*<CRC>\\n

``<CRC>`` is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR)
of the bytes between ``$`` and ``*``, as four upper-case hex digits. A ``\\r`` before the
``\\n`` is tolerated. Lines are at most :data:`MAX_LINE` bytes. doc/explanation/protocol.md is the
full specification (fields, units, examples, error handling); this module is its
reference implementation:

* :func:`encode` turns a frame object into its line (bytes);
* :class:`Parser` is incremental: ``feed(bytes) -> [frames]``; it resynchronises on
  ``$``, and counts (never returns) garbage, partial and over-long lines, bad checksums,
  malformed fields and foreign versions in :class:`ParserStats`;
* :class:`SequenceTracker` detects lost, repeated and reordered sample numbers.

Device -> host: :class:`Sample` (``S``), :class:`Hello` (``H``), :class:`Reset` (``R``),
:class:`Error` (``E``). Host -> device: :class:`Command` (``C``), :class:`Query` (``Q``),
:class:`DriveReadback` (``D``: asks a device that can for the drive it applied, two more fields in every ``S``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

PROTOCOL_VERSION = 1
MAX_LINE = 120  # bytes from '$' to '\n' inclusive
ADC_MAX = 65535  # 16-bit ADC full scale [counts]
SEQ_MODULUS = 1 << 32  # sequence numbers wrap at 2**32
MV_LIMIT = 30000  # |command| <= 30 V, in mV

# Sample flag bits (set by the device).
FLAG_WATCHDOG = 0x01  # device zeroed the drive: no command for its watchdog time
FLAG_CLIPPED = 0x02  # device clipped a command to its driver rating
FLAG_OVERTEMP = 0x04  # device cut the drive on its own over-temperature check
FLAG_BOOT = 0x08  # first sample after boot / reset

_TEXT = re.compile(rb'[A-Za-z0-9_.\-]{0,40}')  # identifiers and error text: no ',', '$', '*'


def _crc_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (check value of b'123456789' is 0x29B1)."""
    crc = 0xFFFF
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ b) & 0xFF]
    return crc


# ----------------------------------------------------------------------------- frames
@dataclass(frozen=True)
class Sample:
    """One synchronous acquisition of all five channels (device -> host, ``S``).

    ``t_us`` is device time since boot [us]; ``adc`` are raw 16-bit counts in the order
    (muscle 1 thermocouple, muscle 2 thermocouple, TEM 1 exchanger face, TEM 2 exchanger
    face, angle potentiometer); calibration to degC / rad is the host's job. ``drive_mV``: the drive
    (u1, u2) [mV] the driver outputs applied over the sample period this sample ends (after the device's clipping,
    watchdog and over-temperature cut), sent only after the host asked with :class:`DriveReadback`; None without.
    """

    seq: int
    t_us: int
    adc: tuple[int, int, int, int, int]
    flags: int = 0
    drive_mV: tuple[int, int] | None = None
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Hello:
    """Device identity (``H``): sent after boot and on a :class:`Query`. ``rate_hz`` = sample rate."""

    device_id: str
    firmware: str
    rate_hz: int
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Reset:
    """The device (re)booted (``R``); its ``seq`` and ``t_us`` restart at 0. ``reason`` e.g. power, watchdog."""

    reason: str
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Error:
    """A device-side error report (``E``): numeric ``code`` and a short ``text``."""

    code: int
    text: str
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Command:
    """TEM drive voltages (host -> device, ``C``) [mV]; ``seq`` counts commands, wraps at 2**32."""

    seq: int
    u1_mV: int
    u2_mV: int
    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class Query:
    """Host asks for a :class:`Hello` (``Q``)."""

    version: int = PROTOCOL_VERSION


@dataclass(frozen=True)
class DriveReadback:
    """Host asks the device to append the drive it applied to every :class:`Sample` (``D``, ``on`` 1) or to stop
    (0), until the device reboots. A device without the read-back ignores it: its samples stay as they were."""

    on: bool = True
    version: int = PROTOCOL_VERSION


Frame = Sample | Hello | Reset | Error | Command | Query | DriveReadback


def _body(frame: Frame) -> str:
    v = frame.version
    if isinstance(frame, Sample):
        a = frame.adc
        d = '' if frame.drive_mV is None else f',{frame.drive_mV[0]},{frame.drive_mV[1]}'
        return f'S,{v},{frame.seq},{frame.t_us},{a[0]},{a[1]},{a[2]},{a[3]},{a[4]},{frame.flags}{d}'
    if isinstance(frame, Command):
        return f'C,{v},{frame.seq},{frame.u1_mV},{frame.u2_mV}'
    if isinstance(frame, Hello):
        return f'H,{v},{frame.device_id},{frame.firmware},{frame.rate_hz}'
    if isinstance(frame, Reset):
        return f'R,{v},{frame.reason}'
    if isinstance(frame, Error):
        return f'E,{v},{frame.code},{frame.text}'
    if isinstance(frame, Query):
        return f'Q,{v}'
    if isinstance(frame, DriveReadback):
        return f'D,{v},{int(frame.on)}'
    raise TypeError(f'not a protocol frame: {frame!r}')


def check_frame(frame: Frame) -> None:
    """Raise ValueError if ``frame`` cannot be encoded (field out of range, bad text)."""
    if not (0 <= frame.version <= 999):
        raise ValueError(f'version {frame.version} outside 0..999')
    if isinstance(frame, Sample):
        if not (0 <= frame.seq < SEQ_MODULUS and 0 <= frame.t_us < 1 << 64 and 0 <= frame.flags <= 0xFFFF):
            raise ValueError(f'sample header out of range: {frame!r}')
        if len(frame.adc) != 5 or not all(0 <= c <= ADC_MAX for c in frame.adc):
            raise ValueError(f'ADC counts must be 5 values in 0..{ADC_MAX}: {frame.adc!r}')
        d = frame.drive_mV
        if d is not None and (len(d) != 2 or not all(abs(x) <= MV_LIMIT for x in d)):
            raise ValueError(f'applied drive must be 2 values within +-{MV_LIMIT} mV: {d!r}')
    elif isinstance(frame, Command):
        if not (0 <= frame.seq < SEQ_MODULUS and abs(frame.u1_mV) <= MV_LIMIT and abs(frame.u2_mV) <= MV_LIMIT):
            raise ValueError(f'command out of range (|u| <= {MV_LIMIT} mV): {frame!r}')
    elif isinstance(frame, Hello):
        if not (
            _TEXT.fullmatch(frame.device_id.encode())
            and _TEXT.fullmatch(frame.firmware.encode())
            and 0 < frame.rate_hz <= 100000
        ):
            raise ValueError(f'bad hello: {frame!r}')
    elif isinstance(frame, Reset):
        if not _TEXT.fullmatch(frame.reason.encode()):
            raise ValueError(f'bad reset reason: {frame.reason!r}')
    elif isinstance(frame, Error):
        if not (0 <= frame.code <= 65535 and _TEXT.fullmatch(frame.text.encode())):
            raise ValueError(f'bad error frame: {frame!r}')


def encode(frame: Frame) -> bytes:
    """The line of ``frame``, ``$...*CRC\\n`` (ValueError if a field is out of range)."""
    check_frame(frame)
    body = _body(frame).encode('ascii')
    return b'$' + body + b'*%04X\n' % crc16(body)


def encode_unchecked(body: str) -> bytes:
    """A line with a correct CRC around an arbitrary body (for tests and fault injection)."""
    b = body.encode('ascii')
    return b'$' + b + b'*%04X\n' % crc16(b)


# ----------------------------------------------------------------------------- parsing
_N = rb'(0|[1-9][0-9]{0,19})'  # unsigned decimal, canonical (no leading zeros, no sign, no '_')
_I = rb'(0|-?[1-9][0-9]{0,5})'  # signed decimal
_T = rb'([A-Za-z0-9_.\-]{0,40})'
_PATTERNS = {
    # a sample's last two fields, the applied drive, are there only when the host asked (DriveReadback)
    ord('S'): re.compile(rb'S,' + b','.join([_N] * 9) + rb'(?:,' + _I + b',' + _I + b')?'),
    ord('C'): re.compile(rb'C,' + _N + b',' + _N + b',' + _I + b',' + _I),
    ord('H'): re.compile(rb'H,' + _N + b',' + _T + b',' + _T + b',' + _N),
    ord('R'): re.compile(rb'R,' + _N + b',' + _T),
    ord('E'): re.compile(rb'E,' + _N + b',' + _N + b',' + _T),
    ord('Q'): re.compile(rb'Q,' + _N),
    ord('D'): re.compile(rb'D,' + _N + rb',([01])'),
}
_HEX = re.compile(rb'[0-9A-F]{4}')


@dataclass
class ParserStats:
    """What the parser saw; every discarded byte or line is counted in exactly one field."""

    frames: int = 0  # valid frames returned
    garbage_bytes: int = 0  # bytes outside any '$'...'\n' line
    partial_lines: int = 0  # a '$' line cut off by another '$' (lost bytes in between)
    overlong_lines: int = 0  # no '\n' within MAX_LINE bytes
    bad_checksum: int = 0  # well-formed '*XXXX' whose CRC does not match
    malformed: int = 0  # no/ill-formed checksum field, unknown type, fields out of range
    version_mismatch: int = 0  # valid frame of another protocol version

    @property
    def rejected_lines(self) -> int:
        return self.partial_lines + self.overlong_lines + self.bad_checksum + self.malformed + self.version_mismatch


def _build(kind: int, g: tuple[bytes, ...]) -> Frame | None:
    """Frame from regex groups (version already checked), or None if a field is out of range."""
    if kind == ord('S'):
        seq, t_us, flags = int(g[1]), int(g[2]), int(g[8])
        adc = (int(g[3]), int(g[4]), int(g[5]), int(g[6]), int(g[7]))
        if seq >= SEQ_MODULUS or t_us >= 1 << 64 or flags > 0xFFFF or max(adc) > ADC_MAX:
            return None
        drive = None if g[9] is None else (int(g[9]), int(g[10]))
        if drive is not None and max(abs(drive[0]), abs(drive[1])) > MV_LIMIT:
            return None
        return Sample(seq, t_us, adc, flags, drive)
    if kind == ord('C'):
        seq, u1, u2 = int(g[1]), int(g[2]), int(g[3])
        if seq >= SEQ_MODULUS or abs(u1) > MV_LIMIT or abs(u2) > MV_LIMIT:
            return None
        return Command(seq, u1, u2)
    if kind == ord('H'):
        rate = int(g[3])
        if not 0 < rate <= 100000:
            return None
        return Hello(g[1].decode(), g[2].decode(), rate)
    if kind == ord('R'):
        return Reset(g[1].decode())
    if kind == ord('E'):
        code = int(g[1])
        return Error(code, g[2].decode()) if code <= 65535 else None
    if kind == ord('D'):
        return DriveReadback(g[1] == b'1')
    return Query()


class Parser:
    """Incremental line parser: bytes in, valid frames out, everything else counted.

    ``feed`` may be called with any chunking of the stream (one byte at a time or many
    lines at once) and returns the same frames. A frame is returned only if its line is
    complete, its CRC matches, every field is canonical and in range and its version is
    ``version``. Bytes before a ``$`` are garbage; a ``$`` inside a line starts a new
    line (the cut-off one is counted as partial).
    """

    def __init__(self, version: int = PROTOCOL_VERSION) -> None:
        self.version = version
        self.stats = ParserStats()
        self.foreign_version: int | None = None  # the version of the last frame of another version
        self._buf = bytearray()

    def reset(self) -> None:
        """Forget buffered bytes (e.g. after reopening the port); statistics are kept."""
        self._buf.clear()

    def feed(self, data: bytes) -> list[Frame]:
        buf = self._buf
        buf += data
        out: list[Frame] = []
        st = self.stats
        pos = 0
        n = len(buf)
        while pos < n:
            start = buf.find(b'$', pos)
            if start < 0:
                st.garbage_bytes += n - pos
                pos = n
                break
            st.garbage_bytes += start - pos
            nl = buf.find(b'\n', start + 1, start + MAX_LINE)
            nxt = buf.find(b'$', start + 1, nl if nl >= 0 else min(n, start + MAX_LINE))
            if nxt >= 0:  # another '$' before the end of this line: this one was cut off
                st.partial_lines += 1
                pos = nxt
                continue
            if nl < 0:
                if n - start >= MAX_LINE:
                    st.overlong_lines += 1
                    pos = start + MAX_LINE
                    continue
                pos = start  # incomplete: keep for the next feed
                break
            line = bytes(buf[start + 1 : nl])
            pos = nl + 1
            frame = self._line(line)
            if frame is not None:
                st.frames += 1
                out.append(frame)
        del buf[:pos]
        return out

    def _line(self, line: bytes) -> Frame | None:
        st = self.stats
        if line.endswith(b'\r'):
            line = line[:-1]
        star = line.rfind(b'*')
        if star < 0 or len(line) - star != 5 or not _HEX.fullmatch(line, star + 1):
            st.malformed += 1
            return None
        body = line[:star]
        if crc16(body) != int(line[star + 1 :], 16):
            st.bad_checksum += 1
            return None
        pattern = _PATTERNS.get(body[0]) if body else None
        m = pattern.fullmatch(body) if pattern is not None else None
        if m is None:
            st.malformed += 1
            return None
        g = m.groups()
        if int(g[0]) != self.version:
            st.version_mismatch += 1
            self.foreign_version = int(g[0])
            return None
        frame = _build(body[0], g)
        if frame is None:
            st.malformed += 1
        return frame


@dataclass
class SequenceTracker:
    """Classifies sample sequence numbers (mod 2**32): in order, lost samples, or going back.

    ``update(seq)`` returns the number of samples lost before ``seq`` (0 when in order),
    or -1 when ``seq`` is not newer than the last one (repeat or reorder, also the sign
    of a device reset), which the caller decides how to treat.
    """

    last: int | None = None
    received: int = 0
    lost: int = 0
    backwards: int = 0
    gaps: int = 0
    _history: list[int] = field(default_factory=list, repr=False)

    def update(self, seq: int) -> int:
        self.received += 1
        if self.last is None:
            self.last = seq
            return 0
        d = (seq - self.last) % SEQ_MODULUS
        if d == 0 or d >= SEQ_MODULUS // 2:
            self.backwards += 1
            return -1
        self.last = seq
        if d > 1:
            self.gaps += 1
            self.lost += d - 1
        return d - 1

    def restart(self) -> None:
        """Forget the last number (device reset: its sequence restarts)."""
        self.last = None


__all__ = [
    'PROTOCOL_VERSION',
    'MAX_LINE',
    'ADC_MAX',
    'SEQ_MODULUS',
    'MV_LIMIT',
    'FLAG_WATCHDOG',
    'FLAG_CLIPPED',
    'FLAG_OVERTEMP',
    'FLAG_BOOT',
    'Sample',
    'Hello',
    'Reset',
    'Error',
    'Command',
    'Query',
    'DriveReadback',
    'Frame',
    'crc16',
    'encode',
    'encode_unchecked',
    'check_frame',
    'Parser',
    'ParserStats',
    'SequenceTracker',
]
