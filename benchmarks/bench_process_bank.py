"""The bank's 8-car scenes as OS processes: do the safety layers hold, and does every car get in?

    python benchmarks/bench_process_bank.py [--scenes circle-8 circle-obstacles-8 warehouse-8]
                                            [--seeds 5] [--out DIR]

Runs ``trustfg sim`` (no dashboard) on each scene for seeds 0..N-1, one run after the
other, and prints each run's line and the totals: runs with every car at its goal, cars at
goal, breaches, the least clearance between cars and from the walls, crashes, command rate
and lateness, replan p95, ticks on a lapsed permit, makespans, how busy the machine was
and each car's share of a core. With fewer cores than the fleet needs the runs are starved
(``trustfg sim`` says "saturated"): that is what they test -- the safety layers must hold
while the processes above them wait for a core. Run it with nothing else on the machine;
a run that does not start is reported and counted. Results:
docs/results/performance.md#fleets-as-os-processes.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.experiments.stats import least_pair_clearance
from trustfg.fleet.launch.launcher import loopback_fleet, run

SCENES = ["circle-8", "circle-obstacles-8", "warehouse-8"]


def line(name: str, seed: int, s: dict) -> str:
    control = [c for c in s["control"].values() if c]
    replans = [r["p95"] for r in s["replan_ms"].values() if r]
    makespan = f"{s['makespan_s']:.1f} s" if s["makespan_s"] else "-"
    return (f"{name:>20} {seed:>4} {sum(s['reached_goal'])}/{len(s['reached_goal'])} "
            f"breaches {len(s['breaches'])} least {least_pair_clearance(s):.3f} m walls {s['obstacle_min_clearance']:.3f} m "
            f"makespan {makespan} Hz >= {min(c['rate_hz'] for c in control):.2f} "
            f"late p99 <= {max(c['jitter_ms_p99'] for c in control):.2f} ms replan p95 <= {max(replans, default=0):.0f} ms "
            f"lapsed {sum(c.get('lease_lapsed', 0) for c in control)} busy {s['machine']['busy_cores']:.2f} "
            f"crashed {s['crashed'] or 'none'}")


def totals(summaries: list[dict], not_started: list[str]) -> str:
    if not summaries:
        return f"no run finished ({len(not_started)} did not start)"
    control = [c for s in summaries for c in s["control"].values() if c]
    replans = [r["p95"] for s in summaries for r in s["replan_ms"].values() if r]
    makespans = [s["makespan_s"] for s in summaries if s["makespan_s"]]
    shares = [v["share_go_first_arrival"] for s in summaries for k, v in s["cpu"].items()
              if k.startswith("car") and v and v.get("share_go_first_arrival")]
    busy = [s["machine"]["busy_cores"] for s in summaries]
    return "\n".join([
        f"runs {len(summaries)} (+{len(not_started)} that did not start: {', '.join(not_started) or 'none'}); "
        f"every car at goal in {sum(all(s['reached_goal']) for s in summaries)}; "
        f"cars at goal {sum(sum(s['reached_goal']) for s in summaries)} of {sum(len(s['reached_goal']) for s in summaries)}",
        f"breaches {sum(len(s['breaches']) for s in summaries)}, least clearance {min(map(least_pair_clearance, summaries)):.3f} m; "
        f"walls {min(s['obstacle_min_clearance'] for s in summaries):.3f} m; crashes {sum(bool(s['crashed']) for s in summaries)}",
        f"commands {min(c['rate_hz'] for c in control):.2f}-{max(c['rate_hz'] for c in control):.2f} Hz, "
        f"lateness p99 <= {max(c['jitter_ms_p99'] for c in control):.2f} ms; "
        f"ticks on a lapsed permit {sum(c.get('lease_lapsed', 0) for c in control)} of {sum(c['sent'] for c in control)}",
        f"replan p95 per car {min(replans):.0f}-{max(replans):.0f} ms; "
        + (f"makespans {min(makespans):.1f}-{max(makespans):.1f} s; " if makespans else "no makespan (a car missing in every run); ")
        + f"busy cores {min(busy):.2f}-{max(busy):.2f}"
        + (f"; a car's share of one core {min(shares):.3f}-{max(shares):.3f}" if shares else ""),
    ])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=SCENES, help="shipped scene names or files (default: %(default)s)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 per scene (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=None, help="keep each run's folder here (default: thrown away)")
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    summaries, not_started = [], []
    with tempfile.TemporaryDirectory() as scratch:
        root = args.out or Path(scratch)
        for name in args.scenes:
            scenario = loopback_fleet(load_scenario(name), None, None, 0.0)
            for seed in range(args.seeds):
                out = root / f"{scenario.name}-{seed}"
                try:
                    summary = run(scenario, out, seed=seed)
                except RuntimeError as exc:  # a car that never came up: say so, go on
                    not_started.append(f"{scenario.name} seed {seed} ({exc})")
                    print(f"{scenario.name:>20} {seed:>4} did not start: {exc}", flush=True)
                    continue
                summaries.append(summary)
                print(line(scenario.name, seed, summary), flush=True)
        if args.out is not None:
            (args.out / "totals.json").write_text(json.dumps({"not_started": not_started, "runs": len(summaries)}))
    print(totals(summaries, not_started))


if __name__ == "__main__":
    main()
