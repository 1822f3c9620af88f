"""The NatNet client's sockets and its exchange on the command port, before frames stream.

Opening the sockets (unicast: an ephemeral port of the client's own; multicast: the data
port shared by every process on the host, joined to the group), the kernel's arrival stamp
of a datagram (SO_TIMESTAMPNS), and the command-port conversation: CONNECT until SERVERINFO
answers, then the model definitions (MODELDEF). Why each socket is set up as it is, and
what each mode does: docs/design/links.md, "Multicast and unicast". The client is the one
user, and these functions log under its name.
"""

from __future__ import annotations

import logging
import socket
import struct
import sys
import time

from . import natnet
from .natnet import ConnectRequest, MessageId, NatNetError, ServerInfo, Version
from .natnet_options import NatNetClientOptions

__all__ = ["NatNetConnectionError", "RECV_BYTES", "arrival", "stamp_arrivals", "command_address",
           "command_socket", "multicast_socket", "connect_packet", "handshake", "model_definitions"]

log = logging.getLogger("trustfg.bridge.natnet_client")

RECV_BYTES = 65536
"""The largest datagram a read takes (UDP's limit)."""

_SO_TIMESTAMPNS = getattr(socket, "SO_TIMESTAMPNS", 35 if sys.platform.startswith("linux") else None)
"""Linux's SO_TIMESTAMPNS (SCM_TIMESTAMPNS in the control message; Python does not name it)."""
_TIMESPEC = struct.Struct("@ll")
"""struct timespec as SO_TIMESTAMPNS hands it: seconds and nanoseconds, native longs."""


class NatNetConnectionError(ConnectionError):
    """The client could not set up its link to the NatNet server (timeout, bad address, ...)."""


def _reuse(sock: socket.socket) -> None:
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    if hasattr(socket, "SO_REUSEPORT"):
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        except OSError:  # defined but not supported by this kernel
            pass


def _receive_buffer(sock: socket.socket, nbytes: int) -> None:
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, nbytes)
    except OSError as exc:
        log.debug("could not set SO_RCVBUF to %d: %s", nbytes, exc)


def stamp_arrivals(sock: socket.socket) -> int:
    """Have the kernel stamp each datagram's arrival (SO_TIMESTAMPNS); the control-message
    buffer size ``recvmsg`` needs for the stamp, 0 where the OS gives none."""
    if _SO_TIMESTAMPNS is None or not hasattr(sock, "recvmsg"):
        return 0
    try:
        sock.setsockopt(socket.SOL_SOCKET, _SO_TIMESTAMPNS, 1)
    except OSError as exc:
        log.debug("no kernel arrival stamps (SO_TIMESTAMPNS): %s", exc)
        return 0
    return socket.CMSG_SPACE(_TIMESPEC.size)


def arrival(ancillary: list, mono: float, real: float) -> float:
    """A datagram's arrival on the monotonic clock, from its SO_TIMESTAMPNS control message
    (the wall clock's stamp, moved by how long ago it was: ``mono`` and ``real`` are the
    two clocks read together); ``mono`` without one. Never later than ``mono``."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(data) >= _TIMESPEC.size:
            seconds, nanoseconds = _TIMESPEC.unpack_from(data)
            return min(mono, mono - (real - (seconds + nanoseconds * 1e-9)))
    return mono


def command_address(o: NatNetClientOptions) -> tuple[str, int]:
    """The server's command port, where CONNECT, KEEPALIVE and requests go."""
    return o.server_address, o.command_port


def command_socket(o: NatNetClientOptions) -> socket.socket:
    """A socket of our own on an ephemeral port: no SO_REUSE* (docs/design/links.md, "Multicast and unicast")."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        _receive_buffer(sock, o.receive_buffer_bytes)
        sock.bind((o.local_address, 0))
        sock.settimeout(o.poll_timeout_s)
    except BaseException:
        sock.close()
        raise
    return sock


def multicast_socket(o: NatNetClientOptions) -> socket.socket:
    """The data port, shared with every process on the host (SO_REUSE*), joined to the group."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        _reuse(sock)
        _receive_buffer(sock, o.receive_buffer_bytes)
        # POSIX: bind to the group so only its datagrams arrive; Windows cannot.
        sock.bind(("" if sys.platform == "win32" else o.multicast_group, o.data_port))
        membership = socket.inet_aton(o.multicast_group) + socket.inet_aton(o.local_address)
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, membership)
        sock.settimeout(o.poll_timeout_s)
    except OSError as exc:
        sock.close()
        raise NatNetConnectionError(
            f"cannot join multicast group {o.multicast_group}:{o.data_port} on interface "
            f"{o.local_address}: {exc}") from exc
    return sock


def connect_packet(o: NatNetClientOptions) -> bytes:
    """CONNECT as NatNet 4.2 (the newest layout the codec knows), asking for ``requested_version``."""
    return natnet.serialize(ConnectRequest(o.client_name, Version(0, 1), natnet.NEWEST_LAYOUT,
                                           requested_version=o.requested_version))


def handshake(sock: socket.socket, o: NatNetClientOptions) -> ServerInfo:
    """CONNECT until SERVERINFO arrives; frames arriving meanwhile are dropped."""
    packet = connect_packet(o)
    start = time.monotonic()
    deadline = start + o.connect_timeout_s
    next_send = start
    while True:
        now = time.monotonic()
        if now >= deadline:
            raise NatNetConnectionError(
                f"no SERVERINFO from NatNet server {o.server_address}:{o.command_port} "
                f"within {o.connect_timeout_s:.1f} s (is it running, streaming "
                f"{'multicast' if o.multicast else 'unicast'}, and is the address right?)")
        if now >= next_send:
            sock.sendto(packet, command_address(o))
            next_send = now + o.connect_retry_s
        sock.settimeout(max(1e-3, min(next_send, deadline) - now))
        try:
            data, _ = sock.recvfrom(RECV_BYTES)
        except socket.timeout:
            continue
        except OSError as exc:  # e.g. ICMP port unreachable reported on Windows
            log.debug("NatNet handshake: %s", exc)
            continue
        if natnet.peek_message_id(data) != MessageId.SERVERINFO:
            continue
        try:
            info = natnet.decode_server_info(natnet.unpack_header(data)[1])
        except NatNetError as exc:
            log.warning("NatNet handshake: bad SERVERINFO: %s", exc)
            continue
        sock.settimeout(o.poll_timeout_s)
        _check_mode(info, o)
        log.info("NatNet server %s %s, NatNet %s", info.app_name, info.app_version,
                 info.natnet_version)
        return info


def model_definitions(sock: socket.socket, o: NatNetClientOptions) -> bytes | None:
    """Ask for MODELDEF on the command socket and wait (briefly) for it; None if none came."""
    sock.sendto(natnet.serialize(natnet.RequestModelDef()), command_address(o))
    deadline = time.monotonic() + min(1.0, o.connect_timeout_s)
    while (left := deadline - time.monotonic()) > 0:
        sock.settimeout(left)
        try:
            data, _ = sock.recvfrom(RECV_BYTES)
        except (socket.timeout, OSError):
            continue
        if natnet.peek_message_id(data) == MessageId.MODELDEF:
            sock.settimeout(o.poll_timeout_s)
            return data
    log.warning("NatNet: no MODELDEF from the server; rigid bodies are known by id only")
    return None


def _check_mode(info: ServerInfo, o: NatNetClientOptions) -> None:
    """A server streaming in the other mode is an error; another group or port, a warning."""
    c = info.connection
    if c is None:
        return
    if c.multicast != o.multicast:
        raise NatNetConnectionError(
            f"NatNet server streams {'multicast' if c.multicast else 'unicast'} but the "
            f"client is configured for {'multicast' if o.multicast else 'unicast'}")
    if o.multicast and (c.multicast_address, c.data_port) != (o.multicast_group, o.data_port):
        log.warning("NatNet server announces %s:%d, client listens on %s:%d",
                    c.multicast_address, c.data_port, o.multicast_group, o.data_port)
