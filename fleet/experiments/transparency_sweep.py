"""``trustfg experiment transparency-sweep``: what trust buys against a liar, and against a
fleet that is simply careful with everyone.

    trustfg experiment transparency-sweep [--seeds 30] [--seed 0] [--scene lab]
        [--misinformation 0.05 0.1 0.2 0.4 0.6 0.8] [--gains 1.5 2 3] [--jobs J] [--cluster ADDRESS] [--out DIR]

Car 1 is the paper's liar (``displaced+false-testimony``) at every misinformation level p,
against each fleet: ``on@g`` (trust on, g_max = g), ``wide@g`` (no trust, every plan
believed, every peer at eps_0 * g) and ``off`` (the paper's baseline). Per cell: seeds with
an honest-liar breach, least honest-liar clearance, median least distance of honest cars
to the liar, false positives and makespan, with 95 % bootstrap intervals
(fleet.experiments.stats). Writes DIR/transparency-sweep/metrics.json and table.md. Why
the sweep: docs/design/experiments.md, "The attack suite and the transparency sweep".
"""

from __future__ import annotations

import dataclasses
import sys
import time

from ...agent.config import Scenario
from ...agent.scenario_files import load_scenario
from ..program import command_parser, configured
from . import stats
from .adversaries import run_summary
from .cluster import ClusterError, cluster_at
from .paper import (
    Progress,
    study_folder,
    study_options,
    trust_off,
    trust_on,
    uniform_wide,
    with_liar,
    write_study,
)
from .workers import parallel


def with_gain(scenario: Scenario, gain: float) -> Scenario:
    return dataclasses.replace(scenario, trust=dataclasses.replace(scenario.trust, epsilon_gain_max=gain))


def fleets(gains: list[float]) -> dict:
    """Every fleet of the sweep by label."""
    made = {"off": trust_off}
    for gain in gains:
        made[f"on@{gain:g}"] = lambda s, g=gain: trust_on(with_gain(s, g))
        made[f"wide@{gain:g}"] = lambda s, g=gain: uniform_wide(with_gain(s, g))
    return made


def table(summary: dict, title: str) -> str:
    rows = [[p, fleet, f"{c['breach_seeds']}/{c['runs']}", f"{c['min_clearance_m']:.3f}", stats.show(c["liar_distance_m"]),
             stats.show(c["false_positive_rate"], 0, True), stats.show(c["makespan_s"], 1)]
            for p, by_fleet in summary.items() for fleet, c in by_fleet.items()]
    return stats.markdown(title, ["misinformation", "fleet", "honest-liar breaches (seeds)", "least clearance (m)",
                                  "distance to the liar (m), median", "false positives", "makespan (s), median"], rows)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg experiment transparency-sweep", __doc__)
    study_options(parser, seeds=30)
    parser.add_argument("--scene", default="lab", help="scene (default: lab, where every route crosses the liar's)")
    parser.add_argument("--misinformation", nargs="+", type=float, default=[0.05, 0.1, 0.2, 0.4, 0.6, 0.8],
                        help="the liar's fractions of false plans (default: 0.05 0.1 0.2 0.4 0.6 0.8)")
    parser.add_argument("--gains", nargs="+", type=float, default=[1.5, 2.0, 3.0],
                        help="g_max of the trust-on and uniformly wide fleets (default: 1.5 2 3)")
    args = parser.parse_args(argv)
    if args.seeds < 1 or any(not 0 < p <= 1 for p in args.misinformation) or any(g < 1 for g in args.gains):
        parser.error("need --seeds >= 1, misinformation within (0, 1] and gains >= 1")
    base = configured("trustfg experiment transparency-sweep", lambda: load_scenario(args.scene))
    out = study_folder(args.out, "transparency-sweep")
    started = time.perf_counter()
    seeds = list(range(args.seed, args.seed + args.seeds))
    made = fleets(args.gains)
    tasks = [(p, fleet, make(with_liar(base, p=p)), seed) for p in args.misinformation
             for fleet, make in made.items() for seed in seeds]
    results: dict = {}
    progress = Progress("transparency-sweep", len(tasks))
    try:
        with cluster_at(args.cluster, args.jobs) as cluster:
            for (p, fleet, _, seed), run in parallel(run_summary, tasks, args.jobs, cluster=cluster):
                results.setdefault(str(p), {}).setdefault(fleet, []).append(run)
                progress.step(f"p {p} {fleet} seed {seed}: liar clearance {run['liar_min_clearance']:.3f} m")
    except ClusterError as exc:
        print(f"trustfg experiment transparency-sweep: {exc}", file=sys.stderr)
        return 2
    progress.done()
    summary = {p: {fleet: stats.cell(runs) for fleet, runs in by_fleet.items()} for p, by_fleet in results.items()}
    report = {"experiment": "transparency-sweep", "scene": args.scene, "seeds": seeds, "summary": summary,
              "runs": results, "wall_time_s": round(time.perf_counter() - started, 1)}
    write_study(out, report, table(summary, f"{args.scene}, car 1 lies, {len(seeds)} seeds per cell"))
    return 0
