"""CPU of a car process at steady state, with 3, 7 and 15 peers.

    python benchmarks/bench_cpu.py [--scenes circle-4 circle-8 circle-16] [--seed 0] [--focus K]

Runs ``trustfg sim`` on each scene (no dashboard) and reads every process's CPU from /proc
(fleet.cpu: a car process with its velocity loop). Printed per scene: each car's share of
one core from the go to the first arrival (mean, min, max), and the sum over every process
against the machine's cores -- near the core count the shares are capped, not the demand.
Then where a car's CPU goes while it drives (``cpu_driving``: the main thread by section of
its loop, its other threads, the velocity loop), and the replans' CPU by how each ended.

``--focus K`` runs every car process but car K's at nice 19 (their velocity loops keep
their priority): car K then takes what it needs, so its share is a car's demand with that
many peers. Results: docs/results/performance.md#cpu-of-a-car-process.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
from collections import Counter
from pathlib import Path

from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.cpu import usable_cores
from trustfg.fleet.launch.launcher import loopback_fleet, run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["circle-4", "circle-8", "circle-16"],
                        help="shipped scene names or files (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--focus", type=int, default=None, metavar="K",
                        help="the other car processes at nice 19: car K's demand, uncapped")
    args = parser.parse_args()
    print(f"car process CPU, share of one core from the go to the first arrival ({usable_cores()} cores)")
    print(f"{'scene':>16} {'peers':>5} {'mean':>6} {'min':>6} {'max':>6} {'all processes':>14} {'replan p95 ms':>14}")
    for name in args.scenes:
        scenario = loopback_fleet(load_scenario(name), None, None, 0.0)
        if args.focus is not None and args.focus not in [car.id for car in scenario.cars]:
            parser.error(f"--focus {args.focus}: {scenario.name} has no car {args.focus}")
        with tempfile.TemporaryDirectory() as folder:
            summary = run(scenario, Path(folder), seed=args.seed, wrap=yielding_except(args.focus))
        window = "share_go_first_arrival"
        entries = [summary["cpu"].get(f"car {i}") or {} for i in summary["car_ids"]]
        if any(entry.get(window) is None for entry in entries):  # no car arrived: no such window
            window = "share"
            print(f"    {scenario.name}: no car arrived (or a car process was not read): "
                  "shares over the whole run instead")
        cars = [entry.get(window) or 0.0 for entry in entries]
        total = sum(entry.get(window) or 0.0 for entry in summary["cpu"].values() if entry)
        p95 = max((r["p95"] for r in summary["replan_ms"].values() if r), default=float("nan"))
        print(f"{scenario.name:>16} {len(cars) - 1:>5} {statistics.mean(cars):>6.3f} {min(cars):>6.3f} "
              f"{max(cars):>6.3f} {total:>14.2f} {p95:>14.1f}")
        print_breakdown(summary)
        print_replan_outcomes(summary)
        if args.focus is not None:
            focus = summary["cpu"].get(f"car {args.focus}") or {}
            print(f"    car {args.focus}, the others at nice 19: {focus.get(window) or float('nan'):.3f} of a core "
                  f"from the go to the first arrival")
            print_breakdown(summary, cars=[args.focus])


def yielding_except(focus: int | None):
    """A process wrapper (fleet.launch.launcher.run's ``wrap``) that starts every car process but
    ``focus``'s at nice 19; None: all as they are."""
    def wrap(name: str, argv: list[str]) -> list[str]:
        if focus is not None and name.startswith("car ") and name != f"car {focus}":
            return ["nice", "-n", "19", *argv]
        return argv
    return wrap


def print_replan_outcomes(summary: dict) -> None:
    """The replans' CPU over the whole run, summed over the cars, by how each ended; then
    how many first plans failed verification, and what they broke."""
    totals: dict[str, list[float]] = {}
    for per_car in summary.get("replan_cpu", {}).values():
        for outcome, entry in (per_car or {}).items():
            total = totals.setdefault(outcome, [0, 0.0])
            total[0] += entry["count"]
            total[1] += entry["cpu_s"]
    cpu = sum(t[1] for t in totals.values())
    if not cpu > 0:
        return
    print("    replans by outcome (all cars, whole run): " + ", ".join(
        f"{outcome} {int(count)} x {seconds / count * 1e3:.1f} ms ({seconds / cpu:.0%})"
        for outcome, (count, seconds) in sorted(totals.items(), key=lambda kv: -kv[1][1])))
    broke: Counter = Counter()
    for per_car in summary.get("first_broke", {}).values():
        broke.update(per_car or {})
    replans = sum(int(count) for count, _ in totals.values())
    print(f"    first plans that failed verification: {sum(broke.values())} of {replans} replans"
          + ("; they broke " + ", ".join(f"{what} {n}" for what, n in broke.most_common()) if broke else ""))


def print_breakdown(summary: dict, cars: list[int] | None = None) -> None:
    """The mean over the cars (or only ``cars``) of each part's share of one core while
    the car drove."""
    parts: dict[str, list[float]] = {}
    for car, entry in summary.get("cpu_driving", {}).items():
        if cars is not None and int(car) not in cars:
            continue
        if not entry or not entry["wall_s"] > 0:
            continue
        wall = entry["wall_s"]
        shares = {f"main: {name}": cpu / wall for name, cpu in entry["sections"].items()}
        shares |= {f"thread: {name}": cpu / wall for name, cpu in entry["threads"].items()}
        shares |= {f"command loop: {name}": cpu / wall for name, cpu in entry["command_loop"].items()}
        for name, value in shares.items():
            parts.setdefault(name, []).append(value)
    if not parts:
        print("    (no car drove: no breakdown)")
        return
    total = sum(statistics.mean(v) for k, v in parts.items() if not k.startswith("main: "))  # sections: of main
    print(f"    while driving, share of one core, mean over {len(next(iter(parts.values())))} cars: "
          f"{total:.3f} in all")
    for name in sorted(parts, key=lambda k: -statistics.mean(parts[k])):
        print(f"    {name:>28} {statistics.mean(parts[name]):6.3f}")


if __name__ == "__main__":
    main()
