"""How much CPU each process of a run uses, from the kernel's own accounting.

``/proc/PID/stat`` holds, in clock ticks, the user and system time of the whole process:
fields 14 (utime) and 15 (stime) sum over all its threads, live and exited (proc(5)).
The share of one core over an interval is the growth of utime + stime over the wall
time between two reads: 1.0 is one core busy all the time, 2.0 two cores.

:class:`CpuMeter` reads every process it is given at each ``sample()`` and keeps the
first read, the last read and named marks (e.g. the go and the first arrival), so a
process that dies early still has the reads it had; ``summary()`` turns them into shares.
Parsing is pure (:func:`parse_stat_ticks`), reading is a thin wrapper around it.
"""

from __future__ import annotations

import os
import time
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
    fleet.command_loop: what one car costs)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            ticks = parse_stat_ticks(f.read())
    except (OSError, ValueError):
        return None
    if children:
        for child in child_pids(pid):
            ticks += read_ticks(child, children=True) or 0
    return ticks


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
