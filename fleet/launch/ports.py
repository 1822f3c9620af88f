"""Ports for processes that are started later: picked now, bound by someone else.

A port found by binding port 0 comes from the kernel's ephemeral range, the same range
the kernel draws from for every socket bound without a port. Between the launcher
picking such a port for car N's Zenoh endpoint and car N binding it, car N's own NatNet
client or car link can be given that very port, and the bus then fails with "Address in
use" on every retry, and car N never comes up. So a port handed to another process is
drawn from below the ephemeral range, where the kernel never hands out ports on its own,
probed free, and never handed out twice by this process.
"""

from __future__ import annotations

import random
import socket
from pathlib import Path

PORT_FLOOR = 20000
"""Below this are well-known services' registered ports (and X11, databases, ...)."""

EPHEMERAL_FALLBACK = (32768, 60999)
"""Linux's default ``ip_local_port_range``, for systems that do not say theirs."""

_handed: set[tuple[int, int]] = set()
_draw = random.SystemRandom()


def ephemeral_range(path: Path = Path("/proc/sys/net/ipv4/ip_local_port_range")) -> tuple[int, int]:
    """The kernel's range for ports bound without a number (low, high)."""
    try:
        low, high = (int(v) for v in path.read_text().split())
    except (OSError, ValueError):
        return EPHEMERAL_FALLBACK
    return low, high


def bindable(port: int, kind: int = socket.SOCK_STREAM, host: str = "127.0.0.1") -> bool:
    """Can a socket of ``kind`` bind ``host:port`` right now?"""
    with socket.socket(socket.AF_INET, kind) as s:
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def free_port(kind: int = socket.SOCK_STREAM, attempts: int = 500) -> int:
    """A port of ``kind`` (TCP by default) for another process to bind: outside the
    ephemeral range, free now, not handed out before by this process."""
    low, high = ephemeral_range()
    lo, hi = (PORT_FLOOR, low) if low - PORT_FLOOR >= 1000 else (high + 1, 65536)
    if hi - lo < 1000:
        raise RuntimeError(f"no room for ports outside the ephemeral range {low}-{high}")
    for _ in range(attempts):
        port = _draw.randrange(lo, hi)
        if (kind, port) in _handed or not bindable(port, kind):
            continue
        _handed.add((kind, port))
        return port
    raise RuntimeError(f"no free port of kind {kind} found in {lo}-{hi - 1} after {attempts} tries")
