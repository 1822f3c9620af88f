"""NatNet client options: where and how :class:`~trustfg.bridge.natnet_client.NatNetClient`
listens, and how a fleet config's ``[natnet]`` table becomes them.

Ports, group and interface default to Motive's, read from :class:`NatNetConfig` (their one
home). What each mode does with these options: docs/design/links.md, "NatNet ingestion".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..agent.config import ConfigError, NatNetConfig
from . import natnet
from .natnet import Version

__all__ = ["NatNetClientOptions", "client_options"]

_DEFAULTS = NatNetConfig()
"""Motive's well-known ports and group, from the one place they are configured."""


@dataclass(frozen=True)
class NatNetClientOptions:
    """Where and how to listen. Ports and addresses as in Motive's streaming pane.

    ``natnet_version`` pins the frame layout (e.g. ``Version(3, 0)``); None learns it from
    SERVERINFO. ``requested_version`` is sent in CONNECT to ask the server for a bitstream
    version (NatNet 4 servers may honour it).
    """

    server_address: str = _DEFAULTS.server
    command_port: int = _DEFAULTS.command_port
    multicast: bool = _DEFAULTS.mode == "multicast"
    multicast_group: str = _DEFAULTS.multicast_group
    data_port: int = _DEFAULTS.data_port
    local_address: str = _DEFAULTS.local_interface
    handshake: bool = True
    natnet_version: Version | None = None
    requested_version: Version | None = None
    client_name: str = "trustfg"
    connect_timeout_s: float = 3.0
    connect_retry_s: float = 0.5
    keepalive_interval_s: float = 1.0
    reconnect_after_s: float = 3.0
    poll_timeout_s: float = 0.05
    close_timeout_s: float = 2.0
    receive_buffer_bytes: int = 1 << 20
    frame_restart_threshold: int = 600
    max_frame_rate_hz: float = 0.0
    """Decode at most this many frames a second (0: every frame); see FrameReceiver."""
    decode_on_read: bool = False
    """Keep the newest frame undecoded until a reader asks for the latest samples; see
    FrameReceiver (no ``on_frame`` then, and no ``max_frame_rate_hz``)."""
    pull: bool = False
    """No socket thread: readers take the waiting datagrams (docs/design/links.md, "Threads: a
    socket thread, or pull")."""

    def __post_init__(self) -> None:
        if self.multicast and not self.handshake and self.natnet_version is None:
            raise ValueError("multicast without handshake needs natnet_version")
        for name in ("connect_timeout_s", "connect_retry_s", "keepalive_interval_s",
                     "reconnect_after_s", "poll_timeout_s", "close_timeout_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0")
        if not (math.isfinite(self.max_frame_rate_hz) and self.max_frame_rate_hz >= 0):
            raise ValueError("max_frame_rate_hz must be >= 0 (0: every frame)")
        if self.decode_on_read and self.max_frame_rate_hz > 0:
            raise ValueError("decode_on_read and max_frame_rate_hz exclude each other")


def client_options(n: NatNetConfig) -> NatNetClientOptions:
    """The client's options from a fleet config's ``[natnet]``; ConfigError for a version
    the codec does not decode."""
    if n.version and n.version not in natnet.STREAM_VERSIONS:
        raise ConfigError(f"natnet.version: {n.version} is not one the bridge decodes "
                          f"({', '.join(natnet.STREAM_VERSIONS)})")
    version = Version.parse(n.version) if n.version else None
    return NatNetClientOptions(
        server_address=n.server, command_port=n.command_port, multicast=n.mode == "multicast",
        multicast_group=n.multicast_group, data_port=n.data_port, local_address=n.local_interface,
        natnet_version=version, handshake=version is None or n.mode == "unicast",
    )
