"""Live view of an embedded-runtime graph: its topics over the Foxglove WebSocket protocol.

Under ROS 2, foxglove_bridge serves a running graph to the Foxglove app; on the embedded runtime nothing
but this does. :class:`LiveServer` (the optional extra ``live``: the ``foxglove-sdk`` package) taps every
topic of the graph, as the bag recorder does, and serves it as foxglove_bridge serves a ROS 2 topic:

* one channel per topic, advertised before the server opens (a topic made later: with its first message),
  with the ROS 2 type name as schema name (``sensor_msgs/msg/Temperature``), the ``ros2msg`` schema encoding and the full message
  definition (the type's text, then each nested type after a ``MSG:`` separator, as rosbag2's MCAP
  files store it), and ``cdr`` message encoding: the app decodes the bytes exactly as from
  foxglove_bridge or from the run's bag (the same serialiser, sma_wrist.runtime.fastcdr);
* log times on the graph's clock (the last /clock, as the bag's), and the server's time (the
  ``time`` capability) from /clock, as foxglove_bridge does with ``use_sim_time`` (it sends it with every
  /clock; here it goes with each batch of messages, :meth:`LiveServer.flush`);
* a latched (transient-local) topic such as /wrist/payload sends its last message again to each new
  subscriber, as a transient-local subscription of the bridge receives it.

The SDK sends from its own threads: a publication costs the graph the encoding and, in batches every
``FLUSH_S`` of wall time, a hand-over to a bounded queue per client (``message_backlog_size``; the oldest
message is dropped when a client does not read), so a client that stops reading does not hold the run back
(``sma-wrist bench --section live``).

:class:`RealTimePacer` holds a simulated graph to a multiple of real time so that it can be watched: the
embedded runtime has no wall clock and otherwise runs as fast as the CPU allows.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from .errors import RuntimeErrorBase

#: how to get the live view's dependency, said in every message about it
LIVE_EXTRA = "pip install 'sma_wrist[live]'"
DEFAULT_PORT = 8765  # foxglove_bridge's default
#: the longest a message waits in the graph's process before it is handed to the server [wall s] (LiveServer.flush)
FLUSH_S = 0.05


class LiveError(RuntimeErrorBase):
    """The live view cannot be served (the SDK is not installed, the address cannot be bound)."""


def require_sdk() -> Any:
    """The ``foxglove`` module of foxglove-sdk, or LiveError saying how to install it."""
    try:
        import foxglove
    except ImportError as exc:
        raise LiveError(
            f'the live view (--foxglove) needs the foxglove-sdk package, which is not installed ({exc}): {LIVE_EXTRA}'
        ) from None
    return foxglove


def parse_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); the host defaults to 127.0.0.1 (this machine only), an IPv6 host is
    written in brackets (``[::1]:8765``). Port 0: any free port (the server says which). ValueError on bad
    input."""
    host, sep, port_text = text.strip().rpartition(':')
    if not sep:
        host, port_text = '', text.strip()
    if host.startswith('[') and host.endswith(']'):
        host = host[1:-1]
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f'{text!r}: expected [HOST:]PORT, e.g. 8765 or 0.0.0.0:8765') from None
    if not 0 <= port <= 65535:
        raise ValueError(f'{text!r}: the port must be in [0, 65535]')
    return host or '127.0.0.1', port


def message_definition(typename: str) -> str:
    """The ``ros2msg`` schema text of a ROS 2 type: its fields, then each nested type after a ``MSG:``
    separator (what rosbag2 stores in MCAP files and foxglove_bridge advertises)."""
    from .messages import TYPESTORE

    return TYPESTORE.generate_msgdef(typename, ros_version=2)[0]


def _bind_error(host: str, port: int, reason: str) -> LiveError:
    hint = '; choose another port with --foxglove [HOST:]PORT' if 'in use' in reason else ''
    return LiveError(f'cannot serve the live view on {host}:{port}: {reason}{hint}')


def _check_bind(host: str, port: int) -> None:
    """LiveError unless ``host:port`` can be bound now (as the server binds it: SO_REUSEADDR, so a port that only
    lingers in TIME_WAIT after a previous run is free)."""
    import socket

    try:
        family, kind, proto, _, addr = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    except socket.gaierror as exc:
        raise LiveError(f'cannot serve the live view on {host}:{port}: unknown host ({exc.strerror})') from None
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(addr)
        except OSError as exc:
            raise _bind_error(host, port, exc.strerror or str(exc)) from None


class LiveServer:
    """A Foxglove WebSocket server for the topics of one embedded-runtime graph.

    Construction checks that the address can be bound (a port in use is an error before anything runs);
    :meth:`attach` taps a graph; :meth:`start`, once the nodes are built, advertises every topic of the graph
    and then opens the server; :meth:`close` (or the ``with`` block) stops it. The server opens only after the
    graph's channels exist because foxglove-sdk 0.30.3 may refuse a subscription to a channel created while a
    client is connected, although it has advertised it ("Unknown channel ID", seen in about 1 of 5 channels
    created during a connection; none of 90 created before it). ``backlog``: messages kept per client that
    does not read (the SDK's default, 1024, is about 0.7 s of the closed loop's ~1500 messages/s).
    ``announce(server)`` is called once it listens (the CLI prints its URL).
    """

    def __init__(
        self,
        host: str = '127.0.0.1',
        port: int = DEFAULT_PORT,
        *,
        name: str = 'sma_wrist',
        backlog: int = 1024,
        announce: Callable[[LiveServer], None] | None = None,
    ) -> None:
        self._fg = require_sdk()
        _check_bind(host, port)
        self._context = self._fg.Context()  # this server's channels only (the SDK's default context is process-wide)
        self.host, self._port, self.name, self.backlog, self._announce = host, port, name, int(backlog), announce
        self._server: Any = None
        self._channels: dict[str, Any] = {}  # topic name -> (foxglove Channel, encoder, latched)
        self._latched: dict[int, tuple[Any, bytes, int]] = {}  # channel id -> (channel, last message, log time)
        self._remove_tap: Callable[[], None] | None = None
        self._clock_ns: Callable[[], int] | None = None
        self._graph: Any = None
        self._pending: list[tuple[Any, bytes, int]] = []  # (channel, CDR, log time) of the current instant
        self._last_flush = 0.0  # perf_counter [s]
        self._time_ns: int | None = None  # the graph's clock at the last /clock, broadcast with the next flush
        self.logged = 0  # messages handed to at least one subscribed client
        self.closed = False

    def start(self) -> LiveServer:
        """Advertise every topic the attached graph has a publisher on (others are advertised with their first
        message), then listen. LiveError when the address cannot be bound."""
        from foxglove.websocket import Capability

        for topic in list(self._graph.topics.values()) if self._graph is not None else []:
            if topic.publishers and topic.name not in self._channels:
                self._channel(topic)
        try:
            self._server = self._fg.start_server(
                name=self.name,
                host=self.host,
                port=self._port,
                capabilities=[Capability.Time],
                supported_encodings=['cdr'],
                server_listener=self,
                context=self._context,
                message_backlog_size=self.backlog,
            )
        except RuntimeError as exc:  # FoxgloveError: Failed to bind port: Address already in use (os error 98)
            raise _bind_error(self.host, self._port, str(exc).removeprefix('FoxgloveError: ')) from None
        if self._announce is not None:
            self._announce(self)
        return self

    @property
    def port(self) -> int:
        return int(self._server.port) if self._server is not None else self._port

    @property
    def url(self) -> str:
        host = f'[{self.host}]' if ':' in self.host else self.host
        return f'ws://{host}:{self.port}'

    # -- graph ---------------------------------------------------------------
    def attach(self, context: Any, clock_ns: Callable[[], int]) -> LiveServer:
        """Serve every topic of ``context``'s graph (those made later too); ``clock_ns``: the graph's clock for
        the log times [ns] (``Runtime`` gives the last /clock, as to its bag recorder)."""
        if self._remove_tap is not None:
            raise LiveError('the live server already serves a graph')
        self._clock_ns = clock_ns
        self._graph = context.graph
        self._remove_tap = context.graph.add_tap(self._tap)
        return self

    def _channel(self, topic: Any) -> tuple[Any, Callable[[Any], bytes], bool]:
        from .fastcdr import encoder_for

        typename = topic.msg_type._TYPE
        schema = self._fg.Schema(name=typename, encoding='ros2msg', data=message_definition(typename).encode())
        channel = self._fg.Channel(topic.name, schema=schema, message_encoding='cdr', context=self._context)
        latched = any(p.qos_profile._is_transient_local() for p in topic.publishers)
        entry = self._channels[topic.name] = (channel, encoder_for(typename), latched)
        return entry

    def _tap(self, topic: Any, msg: Any, t_ns: int) -> None:
        entry = self._channels.get(topic.name)
        if entry is None:
            entry = self._channel(topic)
        channel, encode, latched = entry
        clock = self._clock_ns() if self._clock_ns is not None else t_ns
        if topic.name == '/clock':  # a new instant: the messages so far go out together, then the time
            if time.perf_counter() - self._last_flush >= FLUSH_S:
                self.flush()
            self._time_ns = clock
        if latched:  # kept for the next subscriber (on_subscribe)
            data = topic.cdr(msg, encode)
            self._latched[channel.id()] = (channel, data, clock)
        elif not channel.has_sinks():  # nobody subscribed: no encoding
            return
        else:
            data = topic.cdr(msg, encode)
        self._pending.append((channel.base, data, clock))

    def flush(self) -> None:
        """Hand the messages taken since the last flush to the server, then the graph's time. Every hand-over can
        wake the server's threads, and on a loaded machine each wake-up made the graph's thread wait for the CPU:
        sent one by one as published (and the time with each /clock), the taps of a 30 s unpaced run took 0.24 s
        of CPU time and 3.5 s of wall time (the run 5.5 s; 2-core machine at load 20); in batches every 20 ms of
        wall time 0.15 and 0.9-1.0 s (the run 4.2 s, 3.1 s without a server). Hence batches, every ``FLUSH_S``."""
        self._last_flush = time.perf_counter()
        pending, self._pending = self._pending, []
        for base, data, clock in pending:
            base.log(data, clock, None)  # Channel.log's checks cost half the hand-over (0.26 of 0.57 us)
        self.logged += len(pending)
        if self._time_ns is not None and self._server is not None:
            self._server.broadcast_time(self._time_ns)
            self._time_ns = None

    # -- the SDK's ServerListener (called on its threads) -------------------------------------------------
    def on_subscribe(self, client: Any, channel: Any) -> None:
        last = self._latched.get(channel.id)
        if last is not None:
            ch, data, t = last
            ch.base.log(data, t, None)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass

    # -- teardown ------------------------------------------------------------
    def close(self) -> None:
        """Stop tapping and stop the server (clients see it close). Idempotent."""
        if self.closed:
            return
        self.closed = True
        if self._remove_tap is not None:
            self._remove_tap()
            self._remove_tap = None
        self.flush()
        for channel, _, _ in self._channels.values():
            channel.close()
        if self._server is not None:
            self._server.stop()

    def __enter__(self) -> LiveServer:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class RealTimePacer:
    """Hold a graph's /clock to ``factor`` x real time: a /clock tap that sleeps while sim time is ahead.

    The embedded runtime jumps its virtual clock from one timer to the next; a watched run needs the
    wall clock. A graph that falls behind (a slow machine) is not held back; it catches up at full speed.
    """

    def __init__(self, factor: float, *, slack_s: float = 0.002) -> None:
        if not factor > 0:
            raise ValueError(f'real-time factor {factor!r} must be > 0')
        self.factor = float(factor)
        self.slack_s = float(slack_s)  # sleeps shorter than this are saved up (the sleep call costs ~0.1 ms)
        self._start: tuple[float, int] | None = None  # (wall s, sim ns) at the first /clock
        self._remove: Callable[[], None] | None = None
        self.slept_s = 0.0

    def attach(self, context: Any) -> RealTimePacer:
        self._remove = context.graph.add_tap(self._on_clock, ['/clock'])
        return self

    def _on_clock(self, topic: Any, msg: Any, t_ns: int) -> None:
        sim_ns = msg.clock.sec * 1_000_000_000 + msg.clock.nanosec
        now = time.perf_counter()
        if self._start is None:
            self._start = (now, sim_ns)
            return
        wall0, sim0 = self._start
        ahead = (sim_ns - sim0) / 1e9 / self.factor - (now - wall0)
        if ahead > self.slack_s:
            time.sleep(ahead)
            self.slept_s += ahead

    def close(self) -> None:
        if self._remove is not None:
            self._remove()
            self._remove = None


__all__ = ['DEFAULT_PORT', 'LIVE_EXTRA', 'LiveError', 'LiveServer', 'RealTimePacer', 'message_definition']
__all__ += ['parse_address', 'require_sdk']
