"""A NatNet server that stands in for OptiTrack Motive, encoding with :mod:`bridge.natnet`.

Its **command socket** (``command_port``, 1510) answers as Motive does: CONNECT and
DISCOVERY with SERVERINFO, REQUEST_MODELDEF with MODELDEF, ECHO_REQUEST, REQUEST
"FrameRate", REQUEST_FRAMEOFDATA with the latest frame, DISCONNECT, and anything else with
UNRECOGNIZED_REQUEST. Its **stream** sends FRAMEOFDATA at ``rate_hz`` to the multicast
group, or to every unicast client that keeps itself alive, on absolute deadlines: a tick
it falls behind on is skipped, never sent in a burst. Poses come from ``get_bodies(t)``,
``(id, name, position xyz, quaternion xyzw, tracking_valid)`` per rigid body. Fault knobs,
all off by default: ``drop_rate``, ``noise_std_m``, ``latency_s``, ``occlusions``. An
untracked body streams on with its tracking-valid bit clear and, by default, its last
tracked pose, as Motive does (``untracked_pose``). Design and sources: docs/design/links.md,
"mocap-sim: the hardware, simulated".
"""

from __future__ import annotations

import logging
import socket
import struct
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from ..agent.config import NatNetConfig
from ..bridge import natnet
from ..bridge.natnet import (
    ConnectionInfo,
    Frame,
    MarkerSetDescription,
    MessageId,
    ModelDef,
    NatNetError,
    RigidBody,
    RigidBodyDescription,
    ServerInfo,
    Version,
)

__all__ = ["Occlusion", "NatNetServerOptions", "NatNetServer", "NatNetServerStats",
           "ServedBody"]

log = logging.getLogger(__name__)

ServedBody = (tuple[int, str, Sequence[float], Sequence[float], bool]
              | tuple[int, str, Sequence[float], Sequence[float], bool, float])
"""(id, name, position, quaternion, tracking valid) of a simulated body; with a sixth item,
its mean marker error (m), a body relayed from another NatNet server: served as it came,
no noise added (mocap_sim.relay)."""
BodySource = Callable[[float], Iterable[ServedBody]]

_IDENTITY = (0.0, 0.0, 0.0, 1.0)
_ORIGIN = (0.0, 0.0, 0.0)
_KNOWN_IDS = frozenset(int(m) for m in MessageId)


@dataclass(frozen=True)
class Occlusion:
    """Body ``body_id`` is untracked for ``start_s <= t < end_s``, t = seconds of stream
    time since the server started (tick k is at t = k / rate_hz)."""

    body_id: int
    start_s: float
    end_s: float

    def covers(self, body_id: int, t: float) -> bool:
        return body_id == self.body_id and self.start_s <= t < self.end_s


_DEFAULTS = NatNetConfig()
"""Motive's well-known ports and group, from the one place they are configured."""


@dataclass(frozen=True)
class NatNetServerOptions:
    """Server settings. ``address`` is the interface: command socket, multicast interface.

    Port 0 picks a free port (tests); the actual ports are on the running server.
    """

    natnet_version: Version = natnet.DEFAULT_VERSION
    rate_hz: float = 120.0
    address: str = _DEFAULTS.server
    command_port: int = _DEFAULTS.command_port
    multicast: bool = _DEFAULTS.mode == "multicast"
    multicast_group: str = _DEFAULTS.multicast_group
    data_port: int = _DEFAULTS.data_port
    multicast_ttl: int = 1
    app_name: str = "mocap_sim"
    app_version: Version = Version(0, 1, 0, 0)
    clock_frequency_hz: int = 10_000_000
    first_frame_number: int = 1
    client_timeout_s: float = 5.0
    drop_rate: float = 0.0
    noise_std_m: float = 0.0
    latency_s: float = 0.0
    occlusions: tuple[Occlusion, ...] = ()
    untracked_pose: str = "last_known"
    seed: int = 0
    poll_timeout_s: float = 0.05
    close_timeout_s: float = 2.0

    def __post_init__(self) -> None:
        if self.natnet_version not in natnet.FRAME_VERSIONS:
            raise ValueError(f"natnet_version must be one of "
                             f"{', '.join(map(str, natnet.FRAME_VERSIONS))}")
        if not self.rate_hz > 0:
            raise ValueError("rate_hz must be > 0")
        if not 0.0 <= self.drop_rate <= 1.0:
            raise ValueError("drop_rate must be in [0, 1]")
        if not (self.noise_std_m >= 0.0 and self.latency_s >= 0.0):
            raise ValueError("noise_std_m and latency_s must be >= 0")
        if self.untracked_pose not in ("last_known", "zeros"):
            raise ValueError("untracked_pose must be 'last_known' or 'zeros'")
        if not (self.client_timeout_s > 0 and self.poll_timeout_s > 0):
            raise ValueError("client_timeout_s and poll_timeout_s must be > 0")
        if self.multicast and not 0 < self.data_port < 65536:
            raise ValueError("multicast needs a data_port in 1..65535")


@dataclass(frozen=True)
class NatNetServerStats:
    frames_produced: int = 0  # frames built (sent or dropped by the fault knob)
    frames_dropped: int = 0  # by drop_rate
    frames_sent: int = 0  # frames released to the network (once each, whatever the fan-out)
    datagrams_sent: int = 0
    late_ticks: int = 0  # ticks skipped because the stream thread fell behind
    frame_errors: int = 0  # frames lost because get_bodies raised or encoding failed
    requests: Mapping[str, int] = field(default_factory=dict)  # command datagrams by kind
    clients: int = 0


class NatNetServer:
    """See the module docstring. Use as a context manager.

    The logic is reachable without sockets: :meth:`make_frame` builds tick k's frame and
    :meth:`respond` turns one command datagram into the replies.
    """

    def __init__(self, options: NatNetServerOptions, get_bodies: BodySource,
                 rng: np.random.Generator | None = None) -> None:
        self.options = options
        self._get_bodies = get_bodies
        self._rng = rng if rng is not None else np.random.default_rng(options.seed)
        self._lock = threading.Lock()
        self._clients_changed = threading.Condition(self._lock)
        self._stop = threading.Event()
        self._clients: dict[tuple[str, int], float] = {}
        self._names: dict[int, str] = {}
        self._last_tracked: dict[int, tuple[tuple[float, ...], tuple[float, ...]]] = {}
        self._last_frame_packet: bytes | None = None
        self._requests: Counter[str] = Counter()
        self._produced = self._dropped = self._sent = self._datagrams = 0
        self._late = self._frame_errors = 0
        self._cmd: socket.socket | None = None
        self._data: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._t0 = time.monotonic()

    # -- lifecycle ---------------------------------------------------------------------
    def __enter__(self) -> "NatNetServer":
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def start(self) -> "NatNetServer":
        if self._threads:
            raise RuntimeError("NatNetServer already started")
        o = self.options
        self._cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._cmd.bind((o.address, o.command_port))
            self._cmd.settimeout(o.poll_timeout_s)
            self._data.bind((o.address, 0))
            if o.multicast:
                self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF,
                                      socket.inet_aton(o.address))
                self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, o.multicast_ttl)
                self._data.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        except OSError:
            self._close_sockets()
            raise
        self._remember_names(0.0)
        self._stop.clear()
        self._t0 = time.monotonic()
        self._threads = [threading.Thread(target=self._serve_commands, name="natnet-commands",
                                          daemon=True),
                         threading.Thread(target=self._stream, name="natnet-stream", daemon=True)]
        for t in self._threads:
            t.start()
        log.info("NatNet server %s: commands on %s:%d, %s NatNet %s frames at %.0f Hz",
                 o.app_name, *self.command_address,
                 f"multicast to {o.multicast_group}:{o.data_port}" if o.multicast else "unicast",
                 o.natnet_version, o.rate_hz)
        return self

    def close(self) -> None:
        """Stop both threads (joined within ``close_timeout_s``) and close the sockets."""
        self._stop.set()
        for t in self._threads:
            t.join(self.options.close_timeout_s)
            if t.is_alive():
                log.error("NatNet server thread %s did not stop in time", t.name)
        self._threads = []
        self._close_sockets()

    def _close_sockets(self) -> None:
        for sock in (self._cmd, self._data):
            if sock is not None:
                sock.close()
        self._cmd = self._data = None

    # -- readers -----------------------------------------------------------------------
    @property
    def command_address(self) -> tuple[str, int]:
        if self._cmd is None:
            return self.options.address, self.options.command_port
        return self._cmd.getsockname()

    def clients(self) -> list[tuple[str, int]]:
        with self._lock:
            return list(self._clients)

    def wait_for_clients(self, count: int, timeout_s: float) -> bool:
        """Block until exactly ``count`` unicast clients are registered (False on timeout)."""
        with self._clients_changed:
            return self._clients_changed.wait_for(lambda: len(self._clients) == count,
                                                  timeout_s)

    def stats(self) -> NatNetServerStats:
        with self._lock:
            return NatNetServerStats(self._produced, self._dropped, self._sent, self._datagrams,
                                     self._late, self._frame_errors,
                                     MappingProxyType(dict(self._requests)), len(self._clients))

    def server_info(self) -> ServerInfo:
        o = self.options
        return ServerInfo(o.app_name, o.app_version, o.natnet_version,
                          ConnectionInfo(o.clock_frequency_hz, o.data_port, o.multicast,
                                         o.multicast_group))

    def model_def(self) -> ModelDef:
        with self._lock:
            names = sorted(self._names.items())
        return ModelDef(tuple(RigidBodyDescription(name, body_id) for body_id, name in names)
                        + tuple(MarkerSetDescription(name) for _, name in names)
                        + (MarkerSetDescription("all"),))

    # -- frames ------------------------------------------------------------------------
    def _ticks(self, t_monotonic: float) -> int:
        return int(t_monotonic * self.options.clock_frequency_hz)

    def _remember_names(self, t: float) -> None:
        try:
            bodies = list(self._get_bodies(t))
        except Exception:
            log.exception("get_bodies failed")
            return
        with self._lock:
            self._names.update((int(b[0]), str(b[1])) for b in bodies)

    def make_frame(self, k: int) -> Frame | None:
        """Tick k's frame (faults applied), or None if the drop knob loses it."""
        o = self.options
        t = k / o.rate_hz
        bodies = list(self._get_bodies(t))
        with self._lock:
            self._produced += 1
            self._names.update((int(b[0]), str(b[1])) for b in bodies)
        if o.drop_rate > 0.0 and self._rng.random() < o.drop_rate:
            with self._lock:
                self._dropped += 1
            return None
        rigid_bodies = tuple(self._served_body(b, t) for b in bodies)
        nominal = self._t0 + t
        return Frame(o.first_frame_number + k, rigid_bodies, timestamp=t,
                     camera_mid_exposure_ticks=self._ticks(nominal),
                     camera_data_received_ticks=self._ticks(time.monotonic()))

    def _served_body(self, body: ServedBody, t: float) -> RigidBody:
        body_id, _, position, orientation, valid, *relayed = body
        body_id = int(body_id)
        o = self.options
        tracked = bool(valid) and not any(occ.covers(body_id, t) for occ in o.occlusions)
        if not tracked:
            if o.untracked_pose == "zeros":
                pos, quat = _ORIGIN, _IDENTITY
            else:
                pos, quat = self._last_tracked.get(body_id, (_ORIGIN, _IDENTITY))
            return RigidBody(body_id, tuple(pos), tuple(quat), 0.0, False)
        pos = tuple(float(p) for p in position)
        if relayed:  # a real body's pose and error as its own server gave them: no noise
            quat = tuple(float(q) for q in orientation)
            self._last_tracked[body_id] = (pos, quat)
            return RigidBody(body_id, pos, quat, float(relayed[0]), True)
        if o.noise_std_m > 0.0:
            pos = tuple(float(p) for p in np.asarray(pos) + self._rng.normal(0.0, o.noise_std_m, 3))
        quat = tuple(float(q) for q in orientation)
        self._last_tracked[body_id] = (pos, quat)
        return RigidBody(body_id, pos, quat, o.noise_std_m, True)

    def _stream(self) -> None:
        o = self.options
        period = 1.0 / o.rate_hz
        queue: deque[tuple[float, Frame]] = deque()
        k = 0
        while not self._stop.is_set():
            now = time.monotonic()
            deadline = self._t0 + k * period
            if now >= deadline:
                behind = int((now - deadline) / period)
                if behind:
                    k += behind
                    with self._lock:
                        self._late += behind
                try:
                    frame = self.make_frame(k)
                except Exception:  # the simulator's callable failed: skip this tick
                    frame = None
                    self._frame_error(f"get_bodies failed at tick {k}")
                k += 1
                if frame is not None:
                    queue.append((now + o.latency_s, frame))
            while queue and queue[0][0] <= now:
                frame = queue.popleft()[1]
                try:
                    self._send_frame(frame)
                except Exception:  # e.g. a body id that does not fit the wire: keep going
                    self._frame_error(f"cannot send frame {frame.frame_number}")
            wake = self._t0 + k * period
            if queue:
                wake = min(wake, queue[0][0])
            self._stop.wait(max(0.0, wake - time.monotonic()))

    def _frame_error(self, what: str) -> None:
        with self._lock:
            self._frame_errors += 1
            first = self._frame_errors == 1
        log.log(logging.ERROR if first else logging.DEBUG, "NatNet server: %s", what,
                exc_info=True)

    def _send_frame(self, frame: Frame) -> None:
        o, sock = self.options, self._data
        if sock is None:
            return
        frame = replace(frame, transmit_ticks=self._ticks(time.monotonic()))
        packet = natnet.serialize(frame, o.natnet_version)
        if o.multicast:
            targets = [(o.multicast_group, o.data_port)]
        else:
            targets = self._live_clients(time.monotonic())
        sent = 0
        for addr in targets:
            try:
                sock.sendto(packet, addr)
                sent += 1
            except OSError as exc:
                log.debug("NatNet server: send to %s failed: %s", addr, exc)
        with self._lock:
            self._last_frame_packet = packet
            self._sent += 1
            self._datagrams += sent

    def _live_clients(self, now: float) -> list[tuple[str, int]]:
        limit = self.options.client_timeout_s
        with self._lock:
            for addr in [a for a, seen in self._clients.items() if now - seen > limit]:
                del self._clients[addr]
                self._clients_changed.notify_all()
                log.info("NatNet server: client %s:%d timed out", *addr)
            return list(self._clients)

    # -- commands ----------------------------------------------------------------------
    def _count(self, kind: str) -> None:
        with self._lock:
            self._requests[kind] += 1

    def respond(self, packet: bytes, sender: tuple[str, int], now: float) -> list[bytes]:
        """The replies to one command datagram (and the client bookkeeping it implies)."""
        o = self.options
        try:
            message_id, payload = natnet.unpack_header(packet)
        except NatNetError as exc:
            self._count("malformed")
            log.debug("NatNet server: bad datagram from %s: %s", sender, exc)
            return []
        with self._lock:
            if sender in self._clients:
                self._clients[sender] = now
        if message_id in (MessageId.CONNECT, MessageId.DISCOVERY):
            request = natnet.decode_connect(payload)
            self._count("connect" if message_id == MessageId.CONNECT else "discovery")
            if message_id == MessageId.CONNECT:
                log.info("NatNet server: CONNECT from %s:%d (%s, asks for NatNet %s)",
                         *sender, request.client_name or "?", request.stream_version or "any")
                if not o.multicast:
                    with self._lock:
                        self._clients[sender] = now
                        self._clients_changed.notify_all()
            return [natnet.serialize(self.server_info())]
        if message_id == MessageId.KEEPALIVE:
            self._count("keepalive")
            return []
        if message_id == MessageId.DISCONNECT:
            self._count("disconnect")
            with self._lock:
                if self._clients.pop(sender, None) is not None:
                    self._clients_changed.notify_all()
            return []
        if message_id == MessageId.REQUEST_MODELDEF:
            self._count("modeldef")
            return [natnet.serialize(self.model_def(), o.natnet_version)]
        if message_id == MessageId.REQUEST_FRAMEOFDATA:
            self._count("frame")
            with self._lock:
                last = self._last_frame_packet
            return [last] if last is not None else []
        if message_id == MessageId.ECHO_REQUEST:
            self._count("echo")
            try:
                echo = natnet.deserialize(packet, o.natnet_version)
            except NatNetError:
                return []
            return [natnet.serialize(natnet.EchoResponse(echo.timestamp, self._ticks(now)))]
        if message_id == MessageId.REQUEST:
            command = natnet.deserialize(packet, o.natnet_version).command
            self._count("request")
            if command == "FrameRate":
                return [natnet.serialize(natnet.Response(struct.pack("<f", o.rate_hz)))]
            log.info("NatNet server: unrecognized request %r from %s:%d", command, *sender)
            return [self._unrecognized()]
        if message_id in _KNOWN_IDS:
            self._count("ignored")  # a server-to-client message sent to us
            return []
        self._count("unknown")
        return [self._unrecognized()]

    def _unrecognized(self) -> bytes:
        o = self.options
        return natnet.serialize(natnet.UnrecognizedRequest(o.app_name, o.app_version,
                                                           o.natnet_version))

    def _serve_commands(self) -> None:
        sock = self._cmd
        assert sock is not None
        while not self._stop.is_set():
            try:
                packet, sender = sock.recvfrom(65536)
            except socket.timeout:
                continue
            except OSError as exc:
                if self._stop.is_set():
                    break
                log.debug("NatNet server: command receive: %s", exc)
                continue
            try:
                replies = self.respond(packet, sender, time.monotonic())
            except Exception:  # keep serving: one bad request must not kill the server
                log.exception("NatNet server: failed to answer %s", sender)
                continue
            for reply in replies:
                try:
                    sock.sendto(reply, sender)
                except OSError as exc:
                    log.debug("NatNet server: reply to %s failed: %s", sender, exc)
