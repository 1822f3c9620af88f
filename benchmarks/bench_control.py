"""Per car: command rate and control-loop jitter while the planner replans.

    python benchmarks/bench_control.py [--cars 4] [--seed 0]

Runs ``trustfg sim`` (mocap-sim and one OS process per car on this machine) and reports,
from each car process's own measurements, the rate at which command datagrams left
(target 50 Hz, acceptance >= 48 Hz), how late the control loop's ticks were against
their deadlines (p50 / p99 / max), and the replan times it ran beside them.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.launch.launcher import default_scenario, loopback_fleet, run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cars", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    scenario = loopback_fleet(load_scenario(default_scenario(args.cars)), args.cars, None, 0.0)
    with tempfile.TemporaryDirectory() as folder:
        summary = run(scenario, Path(folder), seed=args.seed)
    print(f"{args.cars} car processes; command loop at 50 Hz beside replanning at 5 Hz")
    print(f"{'car':>4} {'rate Hz':>8} {'jitter p50 ms':>14} {'p99 ms':>8} {'max ms':>8} {'replan med ms':>14} {'p95 ms':>8}")
    for car in map(str, summary["car_ids"]):
        c, r = summary["control"][car], summary["replan_ms"][car]
        print(f"{car:>4} {c['rate_hz']:>8.2f} {c['jitter_ms_p50']:>14.3f} {c['jitter_ms_p99']:>8.3f} "
              f"{c['jitter_ms_max']:>8.3f} {r['median']:>14.2f} {r['p95']:>8.2f}")


if __name__ == "__main__":
    main()
