"""NatNet client: the sockets around the pure codec in :mod:`bridge.natnet`.

:class:`NatNetClient` is the thin I/O layer, a context manager: it owns the socket, the
unicast duties (KEEPALIVE, MODELDEF again when Motive's models change, CONNECT again after
silence) and a socket thread -- or none (``pull``: every read first takes the datagrams
waiting, each stamped with its arrival as the kernel saw it). It feeds a
:class:`FrameReceiver` (:mod:`bridge.natnet_receiver`), the logic that decodes, counts and
keeps the latest pose of every rigid body. Its options are in :mod:`bridge.natnet_options`,
its sockets and the handshake in :mod:`bridge.natnet_sockets`; the names callers use are
re-exported here. It decodes the version SERVERINFO announces (2.x to 4.4) unless
``natnet_version`` pins one, and refuses a newer one. Multicast, unicast, versions and
pulling: docs/design/links.md, "NatNet ingestion".
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from typing import Callable

from . import natnet
from .natnet import Frame, ServerInfo, Version, supports_frames
from .natnet_options import NatNetClientOptions, client_options
from .natnet_receiver import BodySample, FrameReceiver, NatNetStats
from .natnet_sockets import (
    RECV_BYTES,
    NatNetConnectionError,
    arrival,
    command_address,
    command_socket,
    connect_packet,
    handshake,
    model_definitions,
    multicast_socket,
    stamp_arrivals,
)

__all__ = ["NatNetClientOptions", "NatNetClient", "NatNetConnectionError", "FrameReceiver",
           "BodySample", "NatNetStats", "client_options"]

log = logging.getLogger(__name__)


class NatNetClient:
    """Receives NatNet frames in a background thread, or as readers pull them; see the
    module docstring.

    ``on_frame(frame, received_s)`` runs on the socket thread (pulling: in the reader's)
    and must not block (hand the frame to a queue); ``received_s`` is its arrival,
    ``time.monotonic()``.
    Use as a context manager; ``start()`` raises :class:`NatNetConnectionError` when the
    server does not answer or the sockets cannot be set up.
    """

    def __init__(self, options: NatNetClientOptions = NatNetClientOptions(),
                 on_frame: Callable[[Frame, float], None] | None = None) -> None:
        self.options = options
        self._on_frame = on_frame
        self._receiver: FrameReceiver | None = None
        self._sock: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._server_info: ServerInfo | None = None
        self._pulling = threading.Lock()
        """One reader takes the waiting datagrams at a time (pull)."""
        self._stamp_bytes = 0
        """recvmsg's control buffer for the kernel's arrival stamp (pull; 0: none)."""
        self._last_rx = self._next_keepalive = self._next_model = 0.0
        """The unicast duties' clock (module docstring): the last datagram, the next
        KEEPALIVE, the next MODELDEF request."""

    # -- lifecycle ---------------------------------------------------------------------
    def __enter__(self) -> "NatNetClient":
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def start(self) -> "NatNetClient":
        if self._thread is not None:
            raise RuntimeError("NatNetClient already started")
        o = self.options
        try:
            model_packet = None
            if o.multicast:
                if o.handshake:
                    with command_socket(o) as cmd:
                        self._server_info = handshake(cmd, o)
                        model_packet = model_definitions(cmd, o)
                self._sock = multicast_socket(o)
            else:
                self._sock = command_socket(o)
                try:
                    self._server_info = handshake(self._sock, o)
                    self._sock.sendto(natnet.serialize(natnet.RequestModelDef()), self._server)
                except BaseException:
                    self._sock.close()
                    self._sock = None
                    raise
        except OSError as exc:
            if isinstance(exc, NatNetConnectionError):
                raise
            raise NatNetConnectionError(f"cannot set up the NatNet sockets: {exc}") from exc
        version = self._choose_version()
        self._receiver = FrameReceiver(version, self._on_frame, pinned=o.natnet_version is not None,
                                       restart_threshold=o.frame_restart_threshold,
                                       max_rate_hz=o.max_frame_rate_hz, decode_on_read=o.decode_on_read)
        self._receiver.server_info = self._server_info
        if model_packet is not None:
            self._receiver.handle(model_packet, time.monotonic())
        self._stop.clear()
        now = time.monotonic()
        self._last_rx, self._next_keepalive, self._next_model = now, now + o.keepalive_interval_s, now
        if o.pull:
            self._stamp_bytes = stamp_arrivals(self._sock)
            self._sock.setblocking(False)
        else:
            self._thread = threading.Thread(target=self._run, name="natnet-client", daemon=True)
            self._thread.start()
        log.info("NatNet client receiving %s NatNet %s on %s%s", "multicast" if o.multicast
                 else "unicast", version, self.local_address, " (pulled by its readers)" if o.pull else "")
        return self

    def close(self) -> None:
        """Stop the thread (joined within ``close_timeout_s``) and close the socket."""
        thread, self._thread = self._thread, None
        self._stop.set()
        if thread is not None:
            thread.join(self.options.close_timeout_s)
            if thread.is_alive():
                log.error("NatNet client thread did not stop within %.1f s",
                          self.options.close_timeout_s)
        with self._pulling:  # no reader is taking datagrams from it as it closes
            sock, self._sock = self._sock, None
        if sock is not None:
            if not self.options.multicast and self._server_info is not None:
                try:  # polite: lets the server forget us at once
                    sock.sendto(natnet.serialize(natnet.Disconnect()), self._server)
                except OSError:
                    pass
            sock.close()

    # -- readers -----------------------------------------------------------------------
    @property
    def server_info(self) -> ServerInfo | None:
        """The latest SERVERINFO (from the handshake, or a later one on the socket)."""
        if self._receiver is not None and self._receiver.server_info is not None:
            return self._receiver.server_info
        return self._server_info

    @property
    def version(self) -> Version | None:
        return self._receiver.version if self._receiver else None

    @property
    def thread_id(self) -> int | None:
        """The OS id of the socket thread (for its CPU time in /proc); None before start,
        and when pulling (no thread: its work is its readers')."""
        thread = self._thread
        return thread.native_id if thread is not None else None

    @property
    def local_address(self) -> tuple[str, int] | None:
        sock = self._sock
        return sock.getsockname() if sock is not None else None

    @property
    def model(self) -> natnet.ModelDef | None:
        """The server's latest model definitions (None before MODELDEF arrived)."""
        return self._receiver.model if self._receiver else None

    def body_ids(self) -> dict[str, int]:
        """Rigid-body name -> id as Motive names them (empty before MODELDEF arrived)."""
        return self._receiver.body_ids() if self._receiver else {}

    def latest(self, body_id: int) -> BodySample | None:
        self.pump()
        return self._receiver.latest(body_id) if self._receiver else None

    def latest_all(self) -> dict[int, BodySample]:
        self.pump()
        return self._receiver.latest_all() if self._receiver else {}

    def stats(self) -> NatNetStats:
        self.pump()
        return self._receiver.stats() if self._receiver else NatNetStats()

    def wait_for_frames(self, count: int, timeout_s: float) -> bool:
        """Block until ``count`` frames have been accepted since start (False on timeout)."""
        if self._receiver is None:
            raise RuntimeError("NatNetClient not started")
        if not self.options.pull:
            return self._receiver.wait_for_frames(count, timeout_s)
        deadline = time.monotonic() + timeout_s
        while True:
            self.pump()
            if self._receiver.wait_for_frames(count, 0.0):
                return True
            left, sock = deadline - time.monotonic(), self._sock
            if left <= 0 or sock is None:
                return False
            try:
                select.select([sock], [], [], min(left, self.options.poll_timeout_s))
            except (OSError, ValueError):  # closed meanwhile
                return False

    def pump(self) -> int:
        """Pull: take every datagram waiting on the socket and do the unicast duties; the
        number taken (0 with a socket thread, which takes them itself)."""
        receiver = self._receiver
        if not self.options.pull or receiver is None:
            return 0
        with self._pulling:
            sock = self._sock
            if sock is None:
                return 0
            taken = 0
            mono, real = time.monotonic(), time.time()
            while True:
                try:
                    if self._stamp_bytes:
                        data, ancillary, _, _ = sock.recvmsg(RECV_BYTES, self._stamp_bytes)
                        received = arrival(ancillary, mono, real)
                    else:
                        data, _ = sock.recvfrom(RECV_BYTES)
                        received = mono
                except (BlockingIOError, InterruptedError):
                    break
                except OSError as exc:  # e.g. ICMP port unreachable: nothing more to take now
                    log.debug("NatNet receive: %s", exc)
                    break
                if not data:
                    continue
                taken += 1
                self._last_rx = mono
                try:
                    receiver.handle(data, received)
                except Exception:  # a bug must not take the reader down with it
                    log.exception("NatNet client: failed to handle a datagram")
            self._duties(sock, mono)
        return taken

    # -- the server ----------------------------------------------------------------------
    @property
    def _server(self) -> tuple[str, int]:
        return command_address(self.options)

    def _choose_version(self) -> Version:
        o, info = self.options, self._server_info
        if o.natnet_version is not None:
            if info is not None and (info.natnet_version.major, info.natnet_version.minor) != (
                    o.natnet_version.major, o.natnet_version.minor):
                log.warning("NatNet server says version %s, using the configured %s",
                            info.natnet_version, o.natnet_version)
            version = o.natnet_version
        else:
            assert info is not None
            version = info.natnet_version
        if not supports_frames(version):
            self._close_quietly()
            raise NatNetConnectionError(
                f"NatNet {version} frames are not supported (2.x, 3.0, 3.1 and 4.0 to "
                f"{natnet.LATEST_DECODED.major}.{natnet.LATEST_DECODED.minor} are); set natnet_version or "
                "requested_version")
        return version

    def _close_quietly(self) -> None:
        sock, self._sock = self._sock, None
        if sock is not None:
            sock.close()

    # -- the socket thread ---------------------------------------------------------------
    def _duties(self, sock: socket.socket, now: float) -> None:
        """Unicast: MODELDEF again when Motive's models changed, KEEPALIVE, and CONNECT
        again after ``reconnect_after_s`` of silence (module docstring)."""
        o, receiver = self.options, self._receiver
        if o.multicast or receiver is None:
            return
        try:
            if receiver.models_changed and now >= self._next_model:
                sock.sendto(natnet.serialize(natnet.RequestModelDef()), self._server)
                self._next_model = now + 1.0
            if now >= self._next_keepalive:
                sock.sendto(natnet.serialize(natnet.KeepAlive()), self._server)
                self._next_keepalive = now + o.keepalive_interval_s
            if now - self._last_rx > o.reconnect_after_s:
                log.warning("NatNet: nothing received for %.1f s, reconnecting", now - self._last_rx)
                sock.sendto(connect_packet(o), self._server)
                self._last_rx = now
        except OSError as exc:
            log.debug("NatNet send: %s", exc)

    def _run(self) -> None:
        o, sock, receiver = self.options, self._sock, self._receiver
        assert sock is not None and receiver is not None
        while not self._stop.is_set():
            try:
                data, _ = sock.recvfrom(RECV_BYTES)
            except socket.timeout:
                data = None
            except OSError as exc:
                if self._stop.is_set():
                    break
                log.debug("NatNet receive: %s", exc)
                data = None
                self._stop.wait(o.poll_timeout_s)  # no busy loop on a persistent error
            now = time.monotonic()
            if data:
                self._last_rx = now
                try:
                    receiver.handle(data, now)
                except Exception:  # a bug must not kill the only thread that sees poses
                    log.exception("NatNet client: failed to handle a datagram")
            self._duties(sock, now)


def fresh_pose(client: NatNetClient | None, body_id: int, max_age_s: float,
               up_axis: str = "y") -> tuple[tuple[float, float, float], float] | None:
    """A rigid body's latest tracked pose on the ground plane (x, y, yaw) and its age in
    seconds; None without a client, before the body was seen, when Motive lost it, or
    when the pose is older than ``max_age_s``."""
    sample = client.latest(body_id) if client is not None else None
    if sample is None or not sample.body.tracking_valid:
        return None
    age = time.monotonic() - sample.received_s
    if age > max_age_s:
        return None
    return natnet.to_ground_plane(sample.body.position, sample.body.orientation, up_axis), age
