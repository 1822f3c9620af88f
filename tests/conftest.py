"""Shared test helpers: scenarios and their distance fields, free ports, multicast groups,
waiting on conditions, and the leftover checks (processes, ports) the last test runs."""

from __future__ import annotations

import itertools
import os
import socket
import time
from pathlib import Path

import pytest

from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.ports import free_port

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "deploy" / "scenarios"


@pytest.fixture(scope="session")
def intersection():
    return load_scenario(SCENARIOS / "intersection.toml")


@pytest.fixture(scope="session")
def lab():
    return load_scenario(SCENARIOS / "lab.toml")


@pytest.fixture(scope="session")
def intersection_sdf(intersection):
    return build_sdf(intersection.world)


def wait_for(predicate, timeout: float = 5.0, interval: float = 0.01) -> bool:
    """Poll a condition until it holds or the deadline passes (no fixed sleeps)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(interval)
    return predicate()


def pytest_collection_modifyitems(config, items):
    """The leftover check runs last, after every other test has cleaned up."""
    last = [item for item in items if item.nodeid.endswith("test_nothing_is_left_behind")]
    items[:] = [item for item in items if item not in last] + last


def trustfg_processes() -> list[str]:
    """Command lines of running trustfg processes (car, mocap-sim, sim, dashboard)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            argv = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        text = " ".join(a.decode(errors="replace") for a in argv if a)
        try:  # a car process's command loop is spawned: its command line is multiprocessing's
            name = (entry / "comm").read_text().strip()
        except OSError:
            name = ""
        if "-m trustfg" in text or "/trustfg " in text + " " or name.startswith("trustfg-"):
            found.append(f"{entry.name}: {name}: {text}")
    return found


def _parent(pid: str) -> str | None:
    try:
        for line in (Path("/proc") / pid / "status").read_text().splitlines():
            if line.startswith("PPid:"):
                return line.split()[1]
    except OSError:
        pass
    return None


RUNNING_AT_START = {line.split(":")[0] for line in trustfg_processes()}
"""trustfg processes that ran before the suite (a developer's own bank or fleet)."""


def left_behind() -> list[str]:
    """trustfg processes the suite started and did not stop: those not running when it
    began, nor started by one that was (a pool's new worker)."""
    out = []
    for line in trustfg_processes():
        pid, chain = line.split(":")[0], set()
        while pid not in (None, "0", "1") and pid not in chain and pid not in RUNNING_AT_START:
            chain.add(pid)
            pid = _parent(pid)
        if pid not in RUNNING_AT_START:
            out.append(line)
    return out


def _bound_sockets(protos=("tcp", "tcp6", "udp", "udp6")) -> dict[str, tuple[str, int]]:
    """Socket inode -> (protocol, port) of every listening TCP and bound UDP socket on
    this machine (from /proc/net)."""
    sockets = {}
    for proto in protos:
        path = Path("/proc/net") / proto
        for line in path.read_text().splitlines()[1:] if path.exists() else []:
            fields = line.split()
            if proto.startswith("tcp") and fields[3] != "0A":  # LISTEN only
                continue
            sockets[fields[9]] = (proto, int(fields[1].rsplit(":", 1)[1], 16))
    return sockets


def bound_ports() -> set[tuple[str, int]]:
    """(protocol, port) of every listening TCP and bound UDP socket on this machine."""
    return set(_bound_sockets().values())


BOUND_AT_START = bound_ports()


def port_owners(ports: set[tuple[str, int]]) -> dict[tuple[str, int], list[str]]:
    """Which processes hold each of ``ports`` ("pid: command line"), to name a leftover."""
    inodes = {inode: port for inode, port in _bound_sockets().items() if port in ports}
    owners: dict[tuple[str, int], list[str]] = {port: [] for port in ports}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            links = {_readlink(fd) for fd in (entry / "fd").iterdir()}
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace").strip()
        except OSError:  # gone, or not ours to read
            continue
        for inode, port in inodes.items():
            if f"socket:[{inode}]" in links:
                owners[port].append(f"{entry.name}: {cmdline[:200]}")
    return owners


def own_listeners() -> set[tuple[str, int]]:
    """(protocol, port) of the TCP listeners this process (pytest itself) holds."""
    mine = {_readlink(fd) for fd in Path("/proc/self/fd").iterdir()}
    return {port for inode, port in _bound_sockets(("tcp", "tcp6")).items() if f"socket:[{inode}]" in mine}


FIRST_HELD_AFTER: dict[tuple[str, int], str] = {}
"""For each TCP listener the pytest process held after a test, the first such test: a
leftover in the suite's own process then names the test that opened it."""


@pytest.fixture(autouse=True)
def _note_own_listeners(request):
    yield
    for port in own_listeners():
        FIRST_HELD_AFTER.setdefault(port, request.node.nodeid)


def _readlink(path: Path) -> str:
    try:
        return os.readlink(path)
    except OSError:  # an fd closed while we looked
        return ""


# --- UDP ports and multicast groups of their own, for NatNet tests -------------------------

_groups = itertools.count(1)


def next_multicast_group() -> str:
    """A group of its own per test and per process, so parallel runs do not cross-talk."""
    return f"239.253.{1 + os.getpid() % 250}.{1 + next(_groups) % 250}"


@pytest.fixture(scope="session")
def multicast_loopback() -> None:
    """Skip (naming the OS error) unless multicast on the loopback interface works here."""
    group, port = next_multicast_group(), free_port(socket.SOCK_DGRAM)
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        rx.bind((group, port))
        rx.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                      socket.inet_aton(group) + socket.inet_aton("127.0.0.1"))
        rx.settimeout(2.0)
        tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        tx.sendto(b"probe", (group, port))
        rx.recvfrom(16)
    except OSError as exc:
        pytest.skip(f"multicast on loopback is not available here: {exc!r}")
    finally:
        rx.close()
        tx.close()


@pytest.fixture
def multicast_group(multicast_loopback) -> tuple[str, int]:
    return next_multicast_group(), free_port(socket.SOCK_DGRAM)
