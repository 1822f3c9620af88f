"""One E_STOP datagram straight to a car's link, with the standard library alone.

``trustfg stop`` sends its first E_STOPs through :func:`send_e_stop` before anything else
of the program loads (fleet.operator.estop_first); every later datagram goes through a
:class:`~.link.CommandSender`, which resolves its address with :func:`resolve` too. The
bytes come from :func:`.frame.command_datagram`, the one encoder of every command.
"""

from __future__ import annotations

import socket
import time

from .frame import SOURCE_OPERATOR, Flags, command_datagram, new_session

E_STOP_FLAGS = Flags.E_STOP | Flags.STOP | Flags.PING
"""What an operator's e-stop datagram carries: E_STOP (latched), STOP, and PING (answer me)."""


def resolve(address: tuple[str, int], passive: bool) -> tuple[socket.AddressFamily, tuple]:
    """Resolve once (not per datagram), preferring IPv4 so that "localhost" means the same
    address to a sender and a receiver."""
    flags = socket.AI_PASSIVE if passive else 0
    host = address[0] or None
    try:
        infos = socket.getaddrinfo(host, address[1], socket.AF_INET, socket.SOCK_DGRAM, flags=flags)
    except socket.gaierror:
        infos = socket.getaddrinfo(host, address[1], socket.AF_UNSPEC, socket.SOCK_DGRAM, flags=flags)
    family, _, _, _, sockaddr = infos[0]
    return family, sockaddr


def send_e_stop(car_id: int, address: tuple[str, int], key: bytes | None, source: int = SOURCE_OPERATOR) -> None:
    """One E_STOP (with STOP and PING) to car ``car_id`` at ``address``: version 2 with its
    ``key`` (seq 0 of a new session of ``source``), version 1 without. Raises OSError or
    struct.error (a field that does not fit) -- a car latches an E_STOP whatever its
    sequence number or session (:mod:`.receiver`, rule 2), so one datagram is enough
    when it arrives; the caller repeats through a sender."""
    datagram = command_datagram(key, car_id, 0, time.time(), 0.0, 0.0, E_STOP_FLAGS,
                                new_session() if key is not None else 0, source)
    family, sockaddr = resolve(address, passive=False)
    with socket.socket(family, socket.SOCK_DGRAM) as sock:
        sock.sendto(datagram, sockaddr)
