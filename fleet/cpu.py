"""How much CPU each process of a run uses, from the kernel's own accounting.

``/proc/PID/stat`` holds, in clock ticks, the user and system time of the whole process
(fields 14 and 15, over all its threads, live and exited: proc(5)); a share of one core is
the growth of utime + stime over the wall time between two reads. :class:`CpuMeter` reads
every process it is given at each ``sample()`` and keeps the first and last reads and named
marks (the go, the first arrival), so a process that dies early keeps what it had. Parsing
is pure (:func:`parse_stat_ticks`). Inside a car process, :class:`Sections` books the main
thread's CPU to the section of its loop, and :func:`snapshot` / :func:`breakdown` tell
where the car's CPU went while it drove; :func:`machine_load` says whether a run's
processes saturated the cores. docs/design/architecture.md, "CPU accounting".
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

CLOCK_TICKS_PER_S = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def parse_stat_ticks(text: str) -> int:
    """utime + stime (clock ticks) from the text of /proc/PID/stat.

    The command name (field 2) is in parentheses and may itself hold spaces and
    parentheses, so fields are counted from the last ')'. Raises ValueError on text that
    is not a stat line."""
    end = text.rfind(")")
    if end < 0:
        raise ValueError("not a /proc/PID/stat line: no ')'")
    fields = text[end + 1:].split()
    # After the name: field 3 (state) is fields[0], so field k is fields[k - 3].
    if len(fields) < 13:
        raise ValueError(f"not a /proc/PID/stat line: {len(fields)} fields after the name")
    return int(fields[11]) + int(fields[12])


def read_ticks(pid: int, children: bool = False) -> int | None:
    """utime + stime of a process in clock ticks; None if it is gone or unreadable.
    ``children``: with its live descendants' (a car process and its command loop,
    fleet.car.velocity_loop: what one car costs)."""
    ticks = _stat_ticks(f"/proc/{pid}/stat")
    if ticks is None:
        return None
    if children:
        for child in child_pids(pid):
            ticks += read_ticks(child, children=True) or 0
    return ticks


def read_thread_ticks(pid: int) -> dict[int, int]:
    """utime + stime of every live thread of a process, clock ticks by thread id (empty if
    it is gone)."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return {}
    ticks = {int(task): _stat_ticks(f"/proc/{pid}/task/{task}/stat") for task in tasks}
    return {tid: t for tid, t in ticks.items() if t is not None}  # a thread may end between the two


def _stat_ticks(path: str) -> int | None:
    """utime + stime from a stat file of /proc; None if it is gone or unreadable."""
    try:
        with open(path) as f:
            return parse_stat_ticks(f.read())
    except (OSError, ValueError):
        return None


def child_pids(pid: int) -> list[int]:
    """The live children of a process (every thread's, from /proc/PID/task/TID/children)."""
    found = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            with open(f"/proc/{pid}/task/{task}/children") as f:
                found += [int(c) for c in f.read().split()]
    except OSError:
        pass
    return found


@dataclass(frozen=True)
class Read:
    t: float
    """Wall time of the read, seconds (monotonic)."""
    ticks: int


def share(first: Read, last: Read) -> float | None:
    """Share of one core between two reads; None over an empty interval."""
    if last.t <= first.t:
        return None
    return (last.ticks - first.ticks) / CLOCK_TICKS_PER_S / (last.t - first.t)


@dataclass
class CpuMeter:
    """Reads of named processes over a run."""

    pids: dict[str, int] = field(default_factory=dict)
    trees: set[str] = field(default_factory=set)
    """Processes read with their descendants (read_ticks ``children``)."""
    first: dict[str, Read] = field(default_factory=dict)
    last: dict[str, Read] = field(default_factory=dict)
    marks: dict[str, dict[str, Read]] = field(default_factory=dict)

    def watch(self, name: str, pid: int, children: bool = False) -> None:
        self.pids[name] = pid
        if children:
            self.trees.add(name)
        self.sample([name])

    def sample(self, names: list[str] | None = None, mark: str | None = None,
               clock=time.monotonic) -> None:
        """Read every watched process (or ``names``); ``mark`` also keeps this read under
        that name (for shares between marks)."""
        for name in self.pids if names is None else names:
            ticks = read_ticks(self.pids[name], children=name in self.trees)
            if ticks is None:
                continue
            read = Read(clock(), ticks)
            self.first.setdefault(name, read)
            self.last[name] = read
            if mark is not None:
                self.marks.setdefault(mark, {})[name] = read

    def summary(self, since: str | None = None, until: str | None = None) -> dict[str, dict]:
        """Per process: ``cpu_s`` (CPU seconds between its first and last read) and
        ``share`` (of one core, over the run); with ``since``/``until`` marks also
        ``share_<since>_<until>`` over that window (null if a mark is missing)."""
        out = {}
        for name in self.pids:
            first, last = self.first.get(name), self.last.get(name)
            if first is None or last is None:
                out[name] = None
                continue
            entry = {"cpu_s": round((last.ticks - first.ticks) / CLOCK_TICKS_PER_S, 2),
                     "wall_s": round(last.t - first.t, 2), "share": _rounded(share(first, last))}
            if since is not None and until is not None:
                a = self.marks.get(since, {}).get(name)
                b = self.marks.get(until, {}).get(name)
                entry[f"share_{since}_{until}"] = _rounded(share(a, b)) if a and b else None
            out[name] = entry
        return out


def _rounded(value: float | None) -> float | None:
    return None if value is None else round(value, 4)


@dataclass
class Sections:
    """CPU time of one thread by section of a loop: ``book(name)`` books the thread's CPU
    time since the previous booking to ``name``."""

    clock: Callable[[], float] = time.thread_time
    cpu_s: Counter = field(default_factory=Counter)
    _last: float | None = None

    def book(self, name: str) -> None:
        now = self.clock()
        if self._last is not None:
            self.cpu_s[name] += now - self._last
        self._last = now


@dataclass
class Tally:
    """How many of something there were, and the CPU they took."""

    count: int = 0
    cpu_s: float = 0.0

    def add(self, cpu_s: float) -> None:
        self.count += 1
        self.cpu_s += cpu_s


@dataclass(frozen=True)
class Snapshot:
    """One moment of a car's CPU: its main loop's sections and the kernel's per-thread counts
    of the car process and of its command loop (fleet.car.velocity_loop)."""

    t: float
    """Wall time, seconds (monotonic)."""
    sections: dict[str, float]
    threads: dict[int, int]
    loop_pid: int | None
    loop_threads: dict[int, int]


def snapshot(sections: Sections, pid: int, loop_pid: int | None, clock=time.monotonic) -> Snapshot:
    return Snapshot(clock(), dict(sections.cpu_s), read_thread_ticks(pid), loop_pid,
                    read_thread_ticks(loop_pid) if loop_pid is not None else {})


def breakdown(a: Snapshot, b: Snapshot, main_tid: int, natnet_tid: int | None) -> dict:
    """Where a car's CPU went between two snapshots, in seconds of CPU over ``wall_s``:
    ``sections`` of the main thread (what it spent before its first booking is not in
    them); ``threads`` of the car process: ``main``, ``natnet`` (the NatNet
    client's socket thread; none when its readers pull) and ``other`` (Zenoh's and the
    rest); ``command_loop``: ``main`` (its ticks) and ``other`` (its other threads: its
    NatNet client's, when it has one), zero when the loop was not
    the same process at both ends (it died and was restarted). A thread that ended within
    the window is not counted (a running car keeps its threads)."""
    def grown(before: dict[int, int], after: dict[int, int], tids) -> float:
        return round(sum(after[t] - before.get(t, 0) for t in tids if t in after) / CLOCK_TICKS_PER_S, 3)

    threads = b.threads
    named = {main_tid} | ({natnet_tid} if natnet_tid is not None else set())
    loop_pid = a.loop_pid if a.loop_pid == b.loop_pid else None
    loop = b.loop_threads if loop_pid is not None else {}
    return {
        "wall_s": round(b.t - a.t, 3),
        "sections": {name: round(b.sections.get(name, 0.0) - a.sections.get(name, 0.0), 4)
                     for name in sorted(b.sections)},
        "threads": {"main": grown(a.threads, threads, [main_tid]),
                    "natnet": grown(a.threads, threads, [natnet_tid] if natnet_tid is not None else []),
                    "other": grown(a.threads, threads, [t for t in threads if t not in named])},
        "command_loop": {"main": grown(a.loop_threads, loop, [loop_pid]),
                         "other": grown(a.loop_threads, loop, [t for t in loop if t != loop_pid])},
    }


SATURATED = 0.9
"""A run whose processes took this share of the machine's cores from the go to the first
arrival was starved: its replan times and arrivals measure the machine, not the planner."""


def machine_load(cpu: dict[str, dict | None], cores: int, until: str = "first_arrival") -> dict:
    """How busy the run kept the machine from the go ``until`` a mark (the first arrival;
    "end" for a run in which no car arrived, the most starved kind): ``busy_cores`` (the
    processes' shares of one core over that window, ``share_go_<until>``, summed),
    ``cores``, ``saturated`` and ``until``."""
    busy = sum((entry or {}).get(f"share_go_{until}") or 0.0 for entry in cpu.values())
    return {"busy_cores": round(busy, 2), "cores": cores, "saturated": busy >= SATURATED * cores, "until": until}


CAR_SHARE = 0.2
"""About what one car process takes of a core while the fleet drives, its velocity loop
included, with a few peers (docs/results/performance.md#cpu-of-a-car-process). A rough
figure for a warning before a run, not a budget: more peers take more."""
FLEET_SHARE = 0.15
"""About what mocap-sim and the launcher take together, in cores."""


def capacity_note(cars: int, cores: int) -> str | None:
    """What to tell before a run of ``cars`` car processes on ``cores`` cores whose demand,
    by CAR_SHARE and FLEET_SHARE, is more than the cores (None: it fits)."""
    need = cars * CAR_SHARE + FLEET_SHARE
    if need <= cores:
        return None
    return (f"{cars} car processes need about {need:.1f} cores (a car about {CAR_SHARE} of one while it drives, "
            f"measured on 2 cores AMD EPYC) and this machine gives them {cores}: the cars will wait for the CPU, "
            "replans will run late and end in the braking fallback more often, permits may lapse and stop cars, "
            "and the run's timings will measure the machine, not the planner")


def usable_cores() -> int:
    """The cores this process may run on (its affinity: a container or taskset may allow
    fewer than the machine has)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1
