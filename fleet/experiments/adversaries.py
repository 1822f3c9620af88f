"""``trustfg experiment adversaries``: every attack against three fleets, over many seeds.

    trustfg experiment adversaries [--seeds 50] [--seed 0] [--scenes lab intersection]
                                   [--attacks NAME ...] [--variants on off wide]
                                   [--held-out intersection-8 --held-out-seeds 20] [--range M]
                                   [--jobs J] [--cluster ADDRESS] [--out DIR]

Per scene, attack (car 1 lies; ``collude``: cars 1 and 3) and seed, the in-process fleet
runs ``on`` (trust on), ``off`` (the paper's baseline: every plan believed, eps_0) and
``wide`` (every plan believed, every peer at eps_0 * g_max), and the honest fleet under
loss, delay and a skewed clock (``honest-lossy-clock``). Each cell is summarised by
fleet.experiments.stats.cell with 95 % bootstrap intervals; held-out scenes run ``on``
only, reported apart. With ``--range M`` every car sees its peers within M metres only
(``sensing.range_m``), and false positives count only peers seen a while
(fleet.experiments.testimony.sight_summary). Writes DIR/adversaries/metrics.json and table.md.
"""

from __future__ import annotations

import dataclasses
import sys
import time

from ...agent.config import AttackConfig, Scenario
from ...agent.scenario_files import load_scenario
from ..program import command_parser, configured
from . import stats
from .cluster import Cluster, ClusterError, cluster_at
from .paper import (
    Progress,
    run_one,
    study_folder,
    study_options,
    trust_off,
    trust_on,
    uniform_wide,
    with_attack,
    write_study,
)
from .testimony import sight_summary, with_range
from .workers import parallel

LIAR = 1
PARTNER = 3

ATTACKS: dict[str, dict[int, AttackConfig]] = {
    "displaced": {LIAR: AttackConfig("displaced")},
    "forged-future": {LIAR: AttackConfig("forged-future")},
    "forged-past": {LIAR: AttackConfig("forged-past")},
    "bias": {LIAR: AttackConfig("bias")},
    "false-future": {LIAR: AttackConfig("false-future")},
    "false-yield": {LIAR: AttackConfig("false-yield")},
    "on-off": {LIAR: AttackConfig("on-off")},
    "replay": {LIAR: AttackConfig("replay")},
    "false-testimony": {LIAR: AttackConfig("false-testimony")},
    "slander": {LIAR: AttackConfig("slander")},
    "praise": {LIAR: AttackConfig("praise")},
    "framing": {LIAR: AttackConfig("framing")},
    "collude": {LIAR: AttackConfig("collude"), PARTNER: AttackConfig("collude")},
}
"""The attacks of the table, by label: which car runs which attack (config.attacks)."""

SKEWED_CAR = 2


def lossy_clock(scenario: Scenario) -> Scenario:
    """No liar; 30 % of messages lost, 50 +- 20 ms delay, car 2's clock 0.3 s ahead."""
    sim = dataclasses.replace(scenario.sim, message_loss=0.3, message_latency_s=0.03, message_jitter_s=0.04)
    cars = tuple(dataclasses.replace(c, clock_offset_s=0.3) if c.id == SKEWED_CAR else c for c in scenario.cars)
    return dataclasses.replace(scenario, sim=sim, cars=cars)


HONEST = {"honest-lossy-clock": lossy_clock}
"""Honest fleets under faults (trust on only): what trust costs honest cars."""

PLAN_LIES = ("displaced", "forged-future", "forged-past", "false-future", "false-yield", "on-off", "replay",
             "collude")
"""Attacks whose false claims exceed the transparency tolerance somewhere in the plan: they
must be detected within 3 s; the others are bounded otherwise (docs/design/trust.md, "The
attack suite")."""


VARIANTS = {"on": trust_on, "off": trust_off, "wide": uniform_wide}


def run_summary(task: tuple) -> dict:
    """One seed of one fleet, summarised (a RUN dict; the record is dropped to save memory);
    ``task`` ends with the scenario and the seed (what comes before labels it)."""
    *_, scenario, seed = task
    run, record = run_one(scenario, seed)
    return run | (sight_summary(scenario, record) if scenario.sensing.range_m is not None else {})


def run_matrix(scenes: list[str], attacks: list[str], variants: list[str], seeds: list[int], jobs: int,
               label: str = "adversaries", cluster: Cluster | None = None, range_m: float | None = None) -> dict:
    """{scene: {attack: {variant: [RUN, ...]}}} over every combination (on ``cluster`` when
    given; every car seeing ``range_m`` when given)."""
    tasks = []
    for scene in scenes:
        base = load_scenario(scene) if range_m is None else with_range(load_scenario(scene), range_m)
        for attack in attacks:
            honest = attack in HONEST
            attacked = HONEST[attack](base) if honest else with_attack(base, ATTACKS[attack])
            for variant in (["on"] if honest else variants):
                made = VARIANTS[variant](attacked)
                tasks.extend((scene, attack, variant, made, seed) for seed in seeds)
    results: dict = {}
    progress = Progress(label, len(tasks))
    for (scene, attack, variant, _, seed), run in parallel(run_summary, tasks, jobs, cluster=cluster):
        results.setdefault(scene, {}).setdefault(attack, {}).setdefault(variant, []).append(run)
        progress.step(f"{scene} {attack} {variant} seed {seed}: least clearance "
                      f"{run.get('liar_min_clearance', stats.least_pair_clearance(run)):.3f} m")
    progress.done()
    return results


def summarise(results: dict) -> dict:
    return {scene: {attack: {variant: cell(runs) for variant, runs in by_variant.items()}
                    for attack, by_variant in by_attack.items()}
            for scene, by_attack in results.items()}


def cell(runs: list[dict]) -> dict:
    """stats.cell, and with limited sight the longest time an honest car's trust in an
    honest peer it had seen a while stayed below stats.FALSE_POSITIVE_TRUST, and the liars
    seen lying that were trusted again out of sight (fleet.experiments.testimony)."""
    out = stats.cell(runs)
    if "honest_low_in_sight_s" in runs[0]:
        out |= {"honest_low_in_sight_s_max": max(r["honest_low_in_sight_s"] for r in runs),
                "liar_cleared_unseen": sum(r["liar_cleared_unseen"] for r in runs)}
    return out


def _false_positives(c: dict) -> str:
    text = stats.show(c["false_positive_rate"], 0, True)
    if "honest_low_in_sight_s_max" in c:
        text += f" (in sight; below {stats.FALSE_POSITIVE_TRUST:g} at most {c['honest_low_in_sight_s_max']:.1f} s"
        text += f"; liars seen lying trusted again unseen: {c['liar_cleared_unseen']})"
    return text


def table(summary: dict, title: str) -> str:
    """A markdown table: one row per scene, attack and variant."""
    rows = []
    for scene, by_attack in summary.items():
        for attack, by_variant in by_attack.items():
            for variant, c in by_variant.items():
                stuck = c["runs"] - c["all_arrived"]
                makespan = stats.show(c["makespan_s"], 1) + (f" ({stuck} not all arrived)" if stuck else "")
                if "breach_rate" not in c:  # an honest fleet: any breach, no detection
                    rows.append([scene, attack, variant, f"{c['breach_seeds_any']}/{c['runs']} (any pair)",
                                 f"{c['min_clearance_m']:.3f}", "-", "-", "-",
                                 _false_positives(c), makespan])
                    continue
                never = f" ({c['never_detected']} never)" if c["never_detected"] else ""
                rows.append([scene, attack, variant,
                             f"{c['breach_seeds']}/{c['runs']} ({stats.show(c['breach_rate'], 0, True)})",
                             f"{c['min_clearance_m']:.3f}", stats.show(c["detected_3s_rate"], 0, True)
                             + (f" ({c['withdrawn']} withdrawn)" if c.get("withdrawn") else ""),
                             stats.show(c.get("detected_3s_told_rate"), 0, True), stats.show(c["detection_s"], 1) + never,
                             _false_positives(c), makespan])
    return stats.markdown(title, ["scene", "attack", "fleet", "honest-liar breaches (seeds)", "least clearance (m)",
                                  "detected within 3 s of the first lie due",
                                  "... of the first lie told", "detection (s), median", "false positives",
                                  "makespan (s), median"], rows)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg experiment adversaries", __doc__)
    study_options(parser, seeds=50)
    parser.add_argument("--scenes", nargs="+", default=["lab", "intersection"], help="scenes (default: lab intersection)")
    parser.add_argument("--attacks", nargs="+", choices=[*ATTACKS, *HONEST], default=[*ATTACKS, *HONEST],
                        metavar="ATTACK", help=f"attacks (default: all: {', '.join([*ATTACKS, *HONEST])})")
    parser.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS),
                        help="fleets (default: on off wide)")
    parser.add_argument("--held-out", nargs="*", default=["intersection-8"],
                        help="scenes run with trust on only and reported apart (default: intersection-8)")
    parser.add_argument("--held-out-seeds", type=int, default=20, help="seeds per held-out cell (default 20)")
    parser.add_argument("--range", type=float, default=None, dest="range_m",
                        help="every car sees its peers within this many metres only (default: everywhere)")
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.held_out_seeds < 1:
        parser.error("--seeds and --held-out-seeds must be at least 1")
    for scene in args.scenes + args.held_out:
        configured("trustfg experiment adversaries",
                   lambda: load_scenario(scene) if args.range_m is None else with_range(load_scenario(scene),
                                                                                        args.range_m).validate())
    out = study_folder(args.out, "adversaries")
    started = time.perf_counter()
    seeds = list(range(args.seed, args.seed + args.seeds))
    held = list(range(args.seed, args.seed + args.held_out_seeds))
    try:
        with cluster_at(args.cluster, args.jobs) as cluster:
            results = run_matrix(args.scenes, args.attacks, args.variants, seeds, args.jobs, cluster=cluster,
                                 range_m=args.range_m)
            held_results = run_matrix(args.held_out, args.attacks, ["on"], held, args.jobs, "held-out",
                                      cluster, args.range_m) if args.held_out else {}
    except ClusterError as exc:
        print(f"trustfg experiment adversaries: {exc}", file=sys.stderr)
        return 2
    report = {"experiment": "adversaries", "seeds": seeds, "held_out_seeds": held, "liar": LIAR, "partner": PARTNER,
              "attacks": {a: {str(car): dataclasses.asdict(c) for car, c in ATTACKS[a].items()}
                          for a in args.attacks if a in ATTACKS},
              "summary": summarise(results), "held_out": summarise(held_results),
              "runs": results, "held_out_runs": held_results,
              "wall_time_s": round(time.perf_counter() - started, 1)}
    if args.range_m is not None:
        report["range_m"] = args.range_m
    within = "" if args.range_m is None else f", sensing range {args.range_m:g} m"
    text = table(report["summary"], f"{len(seeds)} seeds per cell{within}")
    if held_results:
        text += "\n" + table(report["held_out"], f"held out: trust on, {len(held)} seeds per cell")
    write_study(out, report, text)
    return 0
