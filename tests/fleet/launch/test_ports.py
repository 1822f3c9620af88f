"""Ports handed to other processes never come from the kernel's ephemeral range."""

import socket

import pytest

from trustfg.fleet.launch import ports

pytestmark = pytest.mark.realtime


def test_handed_ports_are_outside_the_ephemeral_range_and_never_repeat():
    low, high = ports.ephemeral_range()
    handed = [ports.free_port(kind) for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM) for _ in range(100)]
    assert not [p for p in handed if low <= p <= high]
    assert len(set(handed[:100])) == 100 and len(set(handed[100:])) == 100
    assert all(ports.bindable(p, socket.SOCK_DGRAM) for p in handed[100:110])


def test_a_range_that_starts_low_leaves_the_ports_above_it(monkeypatch):
    monkeypatch.setattr(ports, "ephemeral_range", lambda: (1024, 40000))
    assert all(40000 < ports.free_port() <= 65535 for _ in range(50))


def test_a_port_in_use_is_skipped(monkeypatch):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        port = ports.free_port(socket.SOCK_DGRAM)
        busy.bind(("127.0.0.1", port))
        draw = ports._draw.randrange
        forced = [port, port]  # the busy port is drawn twice, then the draw is random again
        monkeypatch.setattr(ports._draw, "randrange",
                            lambda lo, hi: forced.pop() if forced else draw(lo, hi))
        assert ports.free_port(socket.SOCK_DGRAM) != port
        assert forced == []


def test_an_unreadable_range_falls_back_to_linux_default(tmp_path):
    bad = tmp_path / "range"
    bad.write_text("not numbers\n")
    assert ports.ephemeral_range(bad) == ports.EPHEMERAL_FALLBACK
    assert ports.ephemeral_range(tmp_path / "missing") == ports.EPHEMERAL_FALLBACK
