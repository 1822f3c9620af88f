"""The paper's experiments, each run with its factor on and off over many seeds.

    trustfg experiment {proximity,consistency,transparency,lab,pipeline,all} [--seed N] [--seeds K]
                       [--out DIR] [--jobs J] [--cluster ADDRESS]
    trustfg experiment adversaries | transparency-sweep | bank | bank-journals ...

The last four are studies with options of their own (:data:`STUDIES`). An experiment
writes DIR/<name>/metrics.json and PNG figures and prints a table; metrics.json holds the
experiment, its scenario and seeds, one RUN per seed and variant (``"on"``, ``"off"`` and
the others of :data:`EXPERIMENTS`; the lab's ``"A"`` is everyone honest) and a summary.
The RUN keys are listed in docs/user-guide.md, "metrics.json"; how the variants are
built, in docs/design/experiments.md, "The paper's experiments".
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib
import json
import logging
import os
import sys
import textwrap
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ...agent import metrics
from ...agent.audit import first_false_claim
from ...agent.config import PAPER_LIAR, AttackConfig, Scenario
from ...agent.scenario_files import load_scenario
from ...agent.world import build_sdf
from ..program import command_parser, configured
from ..sim.in_process import simulate
from ..sim.run_record import RunRecord, fingerprint, motion_summary, plan_outcomes, rounded
from ..sim.trust_record import TRUST_GAP, TRUST_SETTLE_S, positions_at
from . import stats
from .cluster import Cluster, ClusterError, cluster_at, cluster_option
from .workers import parallel

log = logging.getLogger(__name__)

LIAR_ID = 1
LIAR_MISINFORMATION = 0.4


def factors(scenario: Scenario, **switches: bool) -> Scenario:
    return dataclasses.replace(scenario, planner=dataclasses.replace(scenario.planner, **switches))


def with_liar(scenario: Scenario, liar: int = LIAR_ID, p: float = LIAR_MISINFORMATION) -> Scenario:
    """Car ``liar`` publishes falsified plans in a fraction p of messages and lies in its
    testimonies (the paper's liar: attacks ``displaced+false-testimony``)."""
    return with_attack(scenario, {liar: AttackConfig(PAPER_LIAR, {"p": p})})


def with_attack(scenario: Scenario, attacks: dict[int, AttackConfig]) -> Scenario:
    """The scenario with car ``id`` running ``attacks[id]`` (others as they were)."""
    cars = tuple(dataclasses.replace(c, attack=attacks[c.id]) if c.id in attacks else c for c in scenario.cars)
    return dataclasses.replace(scenario, cars=cars)


ALL_ON = dict(proximity=True, consistency=True, transparency=True)
ALL_OFF = dict(proximity=False, consistency=False, transparency=False)
NO_TRUST = dict(proximity=True, consistency=False, transparency=False)
"""The fair "off": avoidance without trust, the proximity hinge at eps_0 from every peer
(with BELIEVING: no plan refused or held wider for want of a check)."""
BELIEVING = dict(reject_plans=False)
"""Trust switches of a fleet without trust: every plan believed as it comes."""


def believing(scenario: Scenario) -> Scenario:
    return dataclasses.replace(scenario, trust=dataclasses.replace(scenario.trust, **BELIEVING))


def no_trust(scenario: Scenario) -> Scenario:
    """The planner without trust factors, believing every plan: eps_0 from every peer."""
    return factors(believing(scenario), **NO_TRUST)


def trust_on(scenario: Scenario) -> Scenario:
    """Every factor, plan rejection, the audit, epsilon from trust."""
    return factors(scenario, **ALL_ON)


def trust_off(scenario: Scenario) -> Scenario:
    """The paper's baseline: no transparency factor (eps_0 for everyone) and every plan
    believed as it comes (trust is still gathered, for the metrics)."""
    return factors(believing(scenario), **(ALL_ON | dict(transparency=False)))


def uniform_wide(scenario: Scenario) -> Scenario:
    """No trust, but every peer kept at eps_0 * g_max: the uniformly careful fleet
    (``trust.epsilon_gain_fixed``, as the bank's "wide" method)."""
    off = trust_off(scenario)
    return dataclasses.replace(off, trust=dataclasses.replace(
        off.trust, epsilon_gain_fixed=scenario.trust.epsilon_gain_max))


def no_avoidance(scenario: Scenario) -> Scenario:
    """The paper's "off": no trust factor, and nothing else that keeps cars apart either
    (plan verification and the proximity guard switched off too)."""
    return dataclasses.replace(factors(scenario, **ALL_OFF),
                               verify=dataclasses.replace(scenario.verify, enabled=False),
                               guard=dataclasses.replace(scenario.guard, enabled=False))


def mechanisms(scenario: Scenario, verify: bool = True, guard: bool = True, deadlock: bool = True) -> Scenario:
    """Every trust factor on, and the pipeline's mechanisms switched as given."""
    return dataclasses.replace(factors(scenario, **ALL_ON),
                               verify=dataclasses.replace(scenario.verify, enabled=verify),
                               guard=dataclasses.replace(scenario.guard, enabled=guard),
                               deadlock=dataclasses.replace(scenario.deadlock, enabled=deadlock))


@dataclass(frozen=True)
class Experiment:
    name: str
    scenario_file: str
    variants: dict[str, Callable[[Scenario], Scenario]]
    question: str


EXPERIMENTS = {
    "proximity": Experiment(
        "proximity", "intersection",
        {"on": functools.partial(factors, **ALL_ON), "fixed": no_trust, "off": no_avoidance},
        "Do the trust factors prevent proximity breaches on conflicting routes? (fixed: no trust factors, "
        "eps_0 from every peer; off: no avoidance, no verification, no guard)"),
    "consistency": Experiment(
        "consistency", "intersection",
        {"on": functools.partial(factors, **ALL_ON),
         "off": functools.partial(factors, **(ALL_ON | dict(consistency=False)))},
        "Does the consistency factor make the cars' accelerations more alike?"),
    "transparency": Experiment(
        "transparency", "lab",
        {"on": lambda s: trust_on(with_liar(s)), "off": lambda s: trust_off(with_liar(s))},
        "Do honest cars keep a wider berth from a car that publishes 40 % misinformation?"),
    "lab": Experiment(
        "lab", "lab",
        {"A": functools.partial(factors, **ALL_ON),
         "on": lambda s: trust_on(with_liar(s)), "off": lambda s: trust_off(with_liar(s))},
        "The paper's lab left turns: A all honest, B car 1 at 40 % misinformation."),
    "pipeline": Experiment(
        "pipeline", "intersection-8",
        {"on": functools.partial(mechanisms),
         "no_verify": functools.partial(mechanisms, verify=False),
         "no_guard": functools.partial(mechanisms, guard=False),
         "no_deadlock": functools.partial(mechanisms, deadlock=False),
         "planner_only": functools.partial(mechanisms, verify=False, guard=False, deadlock=False)},
        "What does each safety mechanism under the planner add (plan verification with its "
        "fallback, the proximity guard, deadlock resolution)?"),
}
PAPER = ("proximity", "consistency", "transparency", "lab")
"""What ``trustfg experiment all`` runs: the paper's experiments."""


# --- one run ---------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _sdf(world):
    return build_sdf(world)


def _truth(record: RunRecord, car: int):
    """Where car (index) ``car`` truly was at given times (linear between recorded steps)."""
    return positions_at(record.times, record.states[:, car, :2])


def run_one(scenario: Scenario, seed: int) -> tuple[dict, RunRecord]:
    """Simulate one seed and summarise it as a RUN dict (docs/user-guide.md, "metrics.json")."""
    record = simulate(scenario, seed, sdf=_sdf(scenario.world))
    return summarise(scenario, record), record


def summarise(scenario: Scenario, record: RunRecord) -> dict:
    run = {"seed": record.seed} | motion_summary(scenario, record, _sdf(scenario.world)) | {
        "trust": rounded(record.trust[-1]),
        "replan_ms_median": round(float(np.median(np.concatenate(record.replan_ms))), 2)
        if any(record.replan_ms) else None,
    } | plan_outcomes(record.counters)
    liars = [record.car_ids.index(i) for i in run.get("liar_ids", [])]
    honest = [i for i in range(len(record.car_ids)) if i not in liars]
    after = record.trust_times >= TRUST_SETTLE_S
    honest_pairs = [record.trust[after][:, a, b] for a in honest for b in honest if a != b]
    run["honest_trust_min_after_settle"] = round(float(np.min(honest_pairs)), 4) if honest_pairs else None
    if liars:
        gaps = [record.trust[after][:, a, [b for b in honest if b != a]].min(axis=1) - record.trust[after][:, a, liar]
                for a in honest for liar in liars]
        run["trust_gap_min_after_settle"] = round(float(np.min(gaps)), 4)
        separated = [metrics.trust_separation(record.trust_times, record.trust, liar, honest, TRUST_GAP) for liar in liars]
        detected = [metrics.trust_detection(record.trust_times, record.trust, liar, honest, TRUST_GAP) for liar in liars]
        run["trust_separated_at_s"] = None if None in separated else max(separated)
        run["trust_detected_at_s"] = None if None in detected else max(detected)
        told = [record.first_lie_s[i] if record.first_lie_s else None for i in liars]
        due = [first_false_claim(record.told[i], _truth(record, i), scenario.trust, after=first)
               if first is not None and record.told and record.told[i] else None for i, first in zip(liars, told)]
        lies, came_due = [t for t in told if t is not None], [t for t in due if t is not None]
        run["first_lie_s"] = round(float(min(lies)), 3) if lies else None
        run["first_lie_due_s"] = round(min(came_due), 3) if came_due else None
        # Each liar timed from its own lies (a colluding pair: the partner's first lie says
        # nothing of when the other's could be caught), from when, after its first lie
        # (beyond plan_reject_m), a false claim of it first came due beyond the tolerance:
        # the first evidence any observer could have. A liar whose lies were all withdrawn
        # in time is timed from the telling. The run's delay is the slowest liar's.
        run["detection_after_told_s"] = detection_delay(detected, told)
        run["detection_delay_s"] = detection_delay(detected, [d if d is not None else t for d, t in zip(due, told)])
    return run


def detection_delay(detected: list[float | None], since: list[float | None]) -> float | None:
    """The longest detection delay over the liars that lied (``since`` not None): each
    liar's detection time less its own ``since``; None if one of them was never caught."""
    delays = [None if caught is None else caught - start for caught, start in zip(detected, since) if start is not None]
    if not delays or None in delays:
        return None
    return round(float(max(delays)), 3)


# --- a whole experiment ------------------------------------------------------------------------


def _job(task: tuple[str, Scenario, int]) -> tuple[dict, RunRecord]:
    _, scenario, seed = task
    return run_one(scenario, seed)


Made = dict[tuple[str, int], tuple[dict, RunRecord]]
"""Runs made so far, by (fingerprint, seed): a run depends on nothing else (fleet.sim.run_record.fingerprint)."""


def run_experiment(name: str, seeds: list[int], out: Path, jobs: int, scenario_file: str | None = None,
                   figures: bool = True, variants: tuple[str, ...] | None = None, made: Made | None = None,
                   cluster: Cluster | None = None) -> dict:
    """Run experiment ``name`` over ``seeds`` (``variants``: only these of its fleets; None: all),
    on ``cluster`` when given, else in ``jobs`` local worker processes.

    ``made``: the runs of the experiments before this one in the same call, which it adds
    its own to. A fleet that two experiments share (proximity's and consistency's "on",
    transparency's and lab's liar fleets) is then run once and taken by both."""
    experiment = EXPERIMENTS[name]
    unknown = sorted(set(variants or ()) - set(experiment.variants))
    if unknown:
        raise ValueError(f"experiment {name} has no variant {', '.join(unknown)} (it has {', '.join(experiment.variants)})")
    source = scenario_file or experiment.scenario_file
    base = load_scenario(source)
    results: dict[str, list[dict]] = {}
    records: dict[str, list[RunRecord]] = {}
    started = time.perf_counter()
    made = {} if made is None else made
    tasks = [(variant, make(base), seed) for variant, make in experiment.variants.items()
             if variants is None or variant in variants for seed in seeds]
    keys = [(fingerprint(scenario), seed) for _, scenario, seed in tasks]
    todo = {key: task for task, key in zip(tasks, keys) if key not in made}  # each fleet and seed once
    if len(todo) < len(tasks):
        print(f"[{name}] {len(tasks) - len(todo)} of {len(tasks)} runs not run again: the same fleet and seed "
              "as a run before them, in this experiment or one before it", file=sys.stderr)
    progress = Progress(f"{name}", len(todo))
    for key, ((variant, _, seed), (run, record)) in zip(todo, parallel(_job, list(todo.values()), jobs, cluster=cluster)):
        made[key] = (run, record)  # parallel yields in the order of its tasks
        progress.step(f"{variant} seed {seed}: min clearance {stats.least_pair_clearance(run):.3f} m")
    progress.done()
    for (variant, _, _), key in zip(tasks, keys):
        run, record = made[key]
        results.setdefault(variant, []).append(dict(run))  # a report's own copy: another may share the run
        records.setdefault(variant, []).append(record)
    report = {
        "experiment": name,
        "scenario": Path(str(source)).name,
        "question": experiment.question,
        "seeds": seeds,
        "variants": results,
        "summary": summary(name, results),
        "wall_time_s": round(time.perf_counter() - started, 1),
    }
    target = out / name
    target.mkdir(parents=True, exist_ok=True)
    (target / "metrics.json").write_text(json.dumps(report, indent=1))
    if figures:
        from . import figures as fig
        fig.experiment_figures(name, base, results, records, target)
    return report


def summary(name: str, results: dict[str, list[dict]]) -> dict:
    out: dict = {}
    for variant, runs in results.items():
        clearance = [stats.least_pair_clearance(r) for r in runs]
        out[variant] = {
            "runs": len(runs),
            "seeds_with_breach": sum(1 for r in runs if r["breaches"]),
            "breaches": sum(len(r["breaches"]) for r in runs),
            "min_clearance_m": round(min(clearance), 4),
            "median_min_clearance_m": round(float(np.median(clearance)), 4),
            "obstacle_min_clearance_m": round(min(r["obstacle_min_clearance"] for r in runs), 4),
            "all_reached_goal": sum(1 for r in runs if all(r["reached_goal"])),
            "makespan_median_s": _median([r["makespan_s"] for r in runs if r["makespan_s"] is not None]),
            "inconsistency_mean": round(float(np.mean([r["inconsistency"] for r in runs])), 4),
            "inconsistency_median": round(float(np.median([r["inconsistency"] for r in runs])), 4),
            "replan_ms_median": _median([r["replan_ms_median"] for r in runs if r["replan_ms_median"] is not None]),
            "success": sum(1 for r in runs if all(r["reached_goal"]) and not r["breaches"]),
            "plans_fallback_share": _share(runs, "fallback"),
            "plans_retry_share": _share(runs, "retry"),
            "deadlocks": sum(r.get("deadlocks", 0) for r in runs),
            "runs_with_deadlock": sum(1 for r in runs if r.get("deadlocks", 0)),
        }
        if runs and "liar_min_distance" in runs[0]:
            liar = [d for r in runs for d in r["liar_min_distance"]]
            separated = [r["trust_separated_at_s"] for r in runs]
            out[variant] |= {
                "liar_min_distance_median_m": round(float(np.median(liar)), 4),
                "honest_trust_min_after_settle": round(min(r["honest_trust_min_after_settle"] for r in runs), 4),
                "trust_gap_min_after_settle": round(min(r["trust_gap_min_after_settle"] for r in runs), 4),
                "trust_separated_at_s_max": None if None in separated else round(max(separated), 2),
            }
    if "on" in out and "off" in out:
        if "liar_min_distance_median_m" in out["on"]:
            out["liar_distance_ratio"] = round(out["on"]["liar_min_distance_median_m"]
                                               / out["off"]["liar_min_distance_median_m"], 3)
        out["inconsistency_on_vs_off"] = [out["on"]["inconsistency_mean"], out["off"]["inconsistency_mean"]]
        on_runs, off_runs = results["on"], results["off"]
        out["inconsistency_lower_with_factor_in_seeds"] = sum(
            1 for a, b in zip(on_runs, off_runs) if a["inconsistency"] < b["inconsistency"])
    return out


def _share(runs: list[dict], outcome: str) -> float | None:
    """The share of all replans of these runs that ended in ``outcome``."""
    total = sum(sum(r["plans"].values()) for r in runs if "plans" in r)
    return round(sum(r["plans"][outcome] for r in runs if "plans" in r) / total, 4) if total else None


def _median(values: list[float]) -> float | None:
    return round(float(np.median(values)), 3) if values else None


# --- printing -------------------------------------------------------------------------------


def print_table(report: dict, stream=sys.stdout) -> None:
    name, s = report["experiment"], report["summary"]
    print(f"\n== {name} ({report['scenario']}, {len(report['seeds'])} seeds): {report['question']}", file=stream)
    cols = ["runs", "seeds_with_breach", "min_clearance_m", "obstacle_min_clearance_m", "all_reached_goal",
            "success", "makespan_median_s", "inconsistency_mean", "replan_ms_median", "plans_retry_share",
            "plans_fallback_share", "deadlocks", "runs_with_deadlock"]
    extra = ["liar_min_distance_median_m", "honest_trust_min_after_settle", "trust_gap_min_after_settle",
             "trust_separated_at_s_max"]
    variants = [v for v in report["variants"]]
    if any(c in s[v] for v in variants for c in extra):
        cols += extra
    width = max(len(c) for c in cols)
    print(f"{'':{width}}  " + "  ".join(f"{v:>10}" for v in variants), file=stream)
    for c in cols:
        print(f"{c:{width}}  " + "  ".join(f"{_fmt(s[v].get(c)):>10}" for v in variants), file=stream)
    for key in ("liar_distance_ratio", "inconsistency_on_vs_off", "inconsistency_lower_with_factor_in_seeds"):
        if key in s:
            print(f"{key}: {s[key]}", file=stream)
    if name == "lab":
        for variant, label in (("A", "A (all honest)"), ("on", "B (car 1 at 40 %)")):
            matrices = np.array([r["min_distance"] for r in report["variants"][variant]])
            print(f"min distance matrix {label}, median over seeds (m):", file=stream)
            print(np.array2string(np.median(matrices, axis=0), precision=2, suppress_small=True), file=stream)


def _fmt(value) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.3f}"
    return str(value)


class Progress:
    """One line per finished job, with a bar when stderr is a terminal."""

    def __init__(self, label: str, total: int, stream=sys.stderr):
        self.label, self.total, self.count, self.stream = label, total, 0, stream
        self.started = time.perf_counter()
        self.tty = stream.isatty()

    def step(self, text: str) -> None:
        self.count += 1
        elapsed = time.perf_counter() - self.started
        eta = elapsed / self.count * (self.total - self.count)
        bar = "#" * int(20 * self.count / self.total)
        line = f"[{self.label}] {self.count}/{self.total} [{bar:<20}] {elapsed:5.0f}s, ~{eta:4.0f}s left  {text}"
        print(("\r" + line[:150].ljust(150)) if self.tty else line, end="" if self.tty else "\n",
              file=self.stream, flush=True)

    def done(self) -> None:
        if self.tty:
            print(file=self.stream)


# --- command line ------------------------------------------------------------------------------


def study_options(parser: argparse.ArgumentParser, seeds: int) -> None:
    """The options every multi-seed study shares: --seed, --seeds, --jobs, --cluster, --out."""
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--seeds", type=int, default=seeds, help=f"seeds per cell (default {seeds})")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="parallel simulations (default: one per core)")
    cluster_option(parser)
    parser.add_argument("--out", type=Path, default=None, help="output folder (default runs/experiment-<time>)")


def study_folder(out: Path | None, name: str) -> Path:
    folder = (out or Path("runs") / time.strftime("experiment-%Y%m%d-%H%M%S")) / name
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def write_study(folder: Path, report: dict, text: str) -> None:
    """metrics.json and table.md of a study, and the table on stdout."""
    (folder / "metrics.json").write_text(json.dumps(report, indent=1))
    (folder / "table.md").write_text(text)
    print(text)
    print(f"wrote {folder.resolve()} in {report['wall_time_s']:.0f} s")


STUDIES = {
    "adversaries": ("adversaries", "every attack against three fleets (trust on, off, wide), over many seeds"),
    "transparency-sweep": ("transparency_sweep", "what trust buys against a liar, against a fleet careful with everyone"),
    "bank": ("bank.runner", "the scenario bank: every scene, many seeds, our pipeline and the baselines"),
    "bank-journals": ("bank.journals", "one table and figure from bank journals as they were recorded"),
    "testimony": ("testimony", "what testimonies buy cars that see only their neighbours: a liar met after a long approach"),
}
"""Experiments with their own options (``trustfg experiment NAME --help``): module and what
it measures; not in "all"."""


def kinds_told() -> str:
    """One entry for each kind of experiment, for the help."""
    about = {name: experiment.question for name, experiment in EXPERIMENTS.items()}
    about["all"] = f"the paper's experiments: {', '.join(PAPER)}"
    about |= {name: text for name, (_, text) in STUDIES.items()}
    lines = [textwrap.fill(text, 88, initial_indent=f"  {name:<20}", subsequent_indent=" " * 22)
             for name, text in about.items()]
    return ("experiments:\n" + "\n".join(lines) + f"\n\n{', '.join(STUDIES)} take options of their own: "
            "trustfg experiment NAME --help")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in STUDIES:
        return importlib.import_module(f".{STUDIES[argv[0]][0]}", __package__).main(argv[1:])
    parser = command_parser("trustfg experiment", __doc__, epilog=kinds_told())
    parser.add_argument("name", choices=[*EXPERIMENTS, "all", *STUDIES], metavar="EXPERIMENT",
                        help="which experiment, from the list below")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--seeds", type=int, default=20, help="number of seeds (default 20)")
    parser.add_argument("--out", type=Path, default=None,
                        help="output folder (default runs/experiment-<time>)")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                        help="parallel simulations (default: one per core)")
    cluster_option(parser)
    parser.add_argument("--scenario", default=None,
                        help="a scenario file or shipped scene's name instead of the experiment's own "
                             "(proximity, consistency: intersection; transparency, lab: lab)")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    out = args.out or Path("runs") / time.strftime("experiment-%Y%m%d-%H%M%S")
    names = list(PAPER) if args.name == "all" else [args.name]
    seeds = list(range(args.seed, args.seed + args.seeds))
    if args.scenario:
        configured("trustfg experiment", lambda: load_scenario(args.scenario))
    made: Made = {}  # `all`: a fleet two experiments share runs once
    try:
        with cluster_at(args.cluster, args.jobs) as cluster:
            for name in names:
                report = run_experiment(name, seeds, out, args.jobs, args.scenario, figures=not args.no_figures,
                                        made=made, cluster=cluster)
                print_table(report)
    except ClusterError as exc:
        print(f"trustfg experiment: {exc}", file=sys.stderr)
        return 2
    print(f"\nwrote {out.resolve()}")
    return 0
