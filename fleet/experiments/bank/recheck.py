"""Rerunning a journal's runs: which come out as they did (fleet.experiments.run_environment says why some don't).

Pure: which runs to rerun, and how a rerun differs from its journal entry.
"""

from __future__ import annotations

import random

FIELDS = ("outcome", "arrived", "makespan_s", "flowtime_s", "least_clearance_m", "obstacle_min_clearance_m",
          "breaches", "counters")
"""What a rerun must repeat to be the same run (wall and CPU time, replan milliseconds and
the journal's bookkeeping are the machine's, not the run's)."""


def pick(runs: list[dict], count: int, seed: int = 0) -> list[dict]:
    """``count`` of ``runs`` (all of them if fewer), drawn without replacement from a
    seeded generator: the same journal and count pick the same runs."""
    if count >= len(runs):
        return list(runs)
    return random.Random(seed).sample(runs, count)


def differences(entry: dict, rerun: dict) -> list[str]:
    """The FIELDS in which the rerun is not its journal entry (empty: the same run)."""
    return [name for name in FIELDS if entry.get(name) != rerun.get(name)]


def line(entry: dict, rerun: dict, here: str) -> str:
    """One rerun, for the progress output: the same, or how not."""
    name = f"{entry['scene']} {entry['method']} seed {entry['seed']}"
    changed = differences(entry, rerun)
    if not changed:
        return f"{name}: the same ({rerun['outcome']}, makespan {rerun['makespan_s']})"
    shown = ", ".join(f"{f} {entry.get(f)} -> {rerun.get(f)}" for f in changed if f != "counters")
    where = "same environment" if entry.get("env") == here else f"journal env {entry.get('env', 'not recorded')}"
    return f"{name}: DIFFERS ({shown or 'counters only'}; {where}, code {entry.get('code', 'not recorded')})"
