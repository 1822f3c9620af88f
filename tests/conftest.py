"""Shared test helpers: scenarios and their distance fields, free ports, multicast groups,
waiting on conditions, the leftover checks (processes, ports) the last test runs, and the
suite's split into two xdist workers (real time, and simulated time at nice 19)."""

from __future__ import annotations

import ast
import functools
import itertools
import os
import socket
import sys
import threading
import time
import traceback
from pathlib import Path

import pytest

from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.launch.ports import free_port

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


# --- two workers: real time in one, simulated time beside it at the lowest priority -------

REAL_TIME_MARKS = frozenset({"realtime", "browser", "faults"})
"""A test module marked with one of these (its module-level ``pytestmark``) keeps time:
sockets, processes, clocks, a browser or network namespaces. Under pytest-xdist
(``pytest -n 2``) those modules run in one worker, in order, at normal priority; every
other module's outcome is simulated time and CPU alone, and runs in a worker of its own at
the lowest CPU priority (nice 19), on the core the real-time tests leave idle (they keep
about one core busy: fleets of car processes, browsers, network namespaces)."""

COMPUTE, REAL_TIME = "compute", "real-time"
WORKERS_DONE = "workers-done"
"""A folder where each xdist worker leaves a file when its session ends: the leftover
check waits for every other worker's."""


@functools.cache
def module_marks(module: str) -> frozenset[str]:
    """The marks a test module sets on all its tests (its ``pytestmark``), read from its
    source: xdist's scheduler sees node ids, not collected items."""
    tree = ast.parse((ROOT / module).read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "pytestmark" for t in node.targets):
            return frozenset(n.attr for n in ast.walk(node.value)
                             if isinstance(n, ast.Attribute) and getattr(n.value, "attr", None) == "mark")
    return frozenset()


def group_of(nodeid: str) -> str:
    """The worker group of a test, from its module's marks (``tests/agent/test_gp.py::...``)."""
    return REAL_TIME if module_marks(nodeid.split("::")[0]) & REAL_TIME_MARKS else COMPUTE


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist, a test dependency
def pytest_xdist_make_scheduler(config, log):
    """With ``-n`` and xdist's default distribution: the two groups, each whole to one
    worker (xdist's scope scheduling, scoped by group instead of by module)."""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class TwoGroups(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return group_of(nodeid)

    return TwoGroups(config, log)


def pytest_sessionstart(session):
    """Before any test (in the controller, or a run without xdist): the network namespaces
    of fault labs whose test run was killed go, so that they do not fail this run's
    leftover check (fleet.faultlab.netem.sweep_stale: labs of live processes stay)."""
    from trustfg.fleet.faultlab import netem

    if getattr(session.config, "workerinput", None) is None and netem.available() is None:
        for tag in netem.sweep_stale():
            print(f"removed the network namespaces of a killed run's fault lab {tag}", file=sys.stderr)


def pytest_collection_modifyitems(config, items):
    """The leftover check runs last, after every other test has cleaned up. A real-time mark
    set on a single test instead of its module is refused: the worker split reads modules."""
    for item in items:
        marks = {mark.name for mark in item.iter_markers()} & REAL_TIME_MARKS
        if marks and not module_marks(item.nodeid.split("::")[0]) & REAL_TIME_MARKS:
            raise pytest.UsageError(f"{item.nodeid}: mark the whole module with pytestmark = "
                                    f"pytest.mark.{sorted(marks)[0]} (the worker split reads module marks)")
    last = [item for item in items if item.nodeid.endswith("test_nothing_is_left_behind")]
    items[:] = [item for item in items if item not in last] + last


def pytest_runtest_setup(item):
    """An xdist worker that runs the compute group yields the CPU to the real-time one:
    nice 19 (its child processes inherit it); without xdist nothing changes."""
    if hasattr(item.config, "workerinput") and group_of(item.nodeid) == COMPUTE:
        if os.getpriority(os.PRIO_PROCESS, 0) < 19:
            os.setpriority(os.PRIO_PROCESS, 0, 19)


def _workers_done_folder(config) -> Path | None:
    """Beside the workers' own temporary folders (xdist gives each one in the run's
    folder, which pytest deletes three runs later)."""
    if getattr(config, "workerinput", None) is None or not config.option.basetemp:
        return None
    return Path(config.option.basetemp).parent / WORKERS_DONE


def pytest_sessionfinish(session):
    folder = _workers_done_folder(session.config)
    if folder is not None:
        folder.mkdir(exist_ok=True)
        (folder / session.config.workerinput["workerid"]).touch()


def other_workers_done(config) -> bool:
    """True once every other xdist worker's session has ended (always, without xdist)."""
    folder = _workers_done_folder(config)
    if folder is None:
        return True
    others = {f"gw{k}" for k in range(config.workerinput["workercount"])} - {config.workerinput["workerid"]}
    return all((folder / name).exists() for name in others)


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
        if port not in FIRST_HELD_AFTER:
            FIRST_HELD_AFTER[port] = f"{request.node.nodeid} (threads then: {_threads_now()})"


def _threads_now() -> str:
    """This process's threads by name, with where a Zenoh close hangs, if one does."""
    frames = sys._current_frames()
    said = []
    for thread in threading.enumerate():
        said.append(thread.name)
        if thread.name == "zenoh-close" and thread.ident in frames:
            said.append("  " + " <- ".join(f"{f.name}:{f.lineno}" for f in traceback.extract_stack(frames[thread.ident])[-3:]))
    return ", ".join(said)


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
