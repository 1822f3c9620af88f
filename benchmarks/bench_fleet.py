"""The in-process fleet at scale: simulated seconds per wall second, and the outcome.

    python benchmarks/bench_fleet.py SCENE [SCENE ...] [--seeds 1] [--trust-record] [--set SECTION.KEY=VALUE ...]

Runs the deterministic in-process fleet (fleet.sim.in_process: every car's agent, planner and
trust, message codec and inboxes, unicycles and tracking, in one process) on each scene
to completion (every car at its goal) or the scene's timeout, and prints per run: cars,
simulated time, wall time, speed (simulated seconds per wall second, and per CPU second of
this process: steadier on a shared machine), breaches, the least
clearance, whether every car arrived, the replan time median / p95 and how many of the
peers the planners left out as out of reach. The fleet runs as the scenario bank runs it:
without the paper's experiments' sample of every car's trust in every peer every 0.1 s
(``--trust-record`` adds it; O(cars^2) fusions, bookkeeping of the experiment rather than
work of a car). ``--set`` changes a config value of every scene, as the scenario bank's
does (e.g. ``--set verify.keep_s=1.0``). A short unmeasured run first compiles the kernels.
A 32-car scene:

    trustfg scenario generate --kind circle --cars 32 --seed 1 --out circle-32.toml
    python benchmarks/bench_fleet.py circle-32.toml
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.bank.runner import parse_settings, scene_data, variant
from trustfg.fleet.sim.in_process import simulate
from trustfg.fleet.sim.run_record import motion_summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenes", nargs="+", help="shipped scene names or files")
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0..N-1 per scene (default %(default)s)")
    parser.add_argument("--trust-record", action="store_true",
                        help="also sample every car's trust in every peer, as the paper's experiments do")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="change a config value of every scene (VALUE in TOML), as the scenario bank does")
    args = parser.parse_args()
    try:
        settings = parse_settings(args.set)
        scenarios = [variant(scene_data(name)[0], settings) for name in args.scenes]  # bad input fails here, once
    except ConfigError as exc:
        parser.error(str(exc))
    print(f"{'scene':>12} {'seed':>4} {'cars':>4} {'sim s':>6} {'wall s':>7} {'sim/wall':>8} {'sim/cpu':>7} {'breaches':>8} "
          f"{'clear m':>7} {'arrived':>7} {'replan ms med/p95':>18} {'out of reach':>12}")
    warm = load_scenario("intersection")
    simulate(warm, 1000, build_sdf(warm.world), record_trust=args.trust_record)  # numba's kernels compiled
    for scenario in scenarios:
        sdf = build_sdf(scenario.world)
        for seed in range(args.seeds):
            started, started_cpu = time.perf_counter(), time.process_time()
            record = simulate(scenario, seed, sdf, record_trust=args.trust_record)
            wall, cpu = time.perf_counter() - started, time.process_time() - started_cpu
            summary = motion_summary(scenario, record, sdf)
            replans = np.concatenate([np.asarray(r, dtype=float) for r in record.replan_ms])
            left_out = sum(c.get("peers_out_of_reach", 0) for c in record.counters)
            sim_s = float(record.times[-1])
            clearance = np.array(summary["min_clearance"], dtype=float)
            clearance = float(clearance[~np.eye(len(clearance), dtype=bool)].min())
            print(f"{scenario.name:>12} {seed:>4} {len(record.car_ids):>4} {sim_s:>6.1f} {wall:>7.1f} "
                  f"{sim_s / wall:>8.3f} {sim_s / cpu:>7.3f} {len(summary['breaches']):>8} {clearance:>7.3f} "
                  f"{sum(summary['reached_goal']):>3}/{len(record.car_ids):<3} "
                  f"{np.median(replans):>8.1f}/{np.percentile(replans, 95):<9.1f} {left_out:>12}", flush=True)


if __name__ == "__main__":
    main()
