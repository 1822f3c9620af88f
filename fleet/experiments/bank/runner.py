"""The scenario bank: every scene, many seeds, our pipeline and the baselines a user would pick.

    trustfg experiment bank [--scenes NAME|FILE ...] [--seed S] [--seeds K] [--methods M ...]
                            [--fresh K] [--set SECTION.KEY=VALUE ...] [--vehicle in-place|car
                            [--min-turn-radius M]] [--jobs J] [--cluster ADDRESS] [--out DIR]
                            [--report-only | --recheck K]

Per scene, method and seed, one in-process run, with the same departures for every method:
``full`` (the pipeline as shipped), ``fixed`` (no trust factors, every plan believed, eps_0
from every peer), ``wide`` (the same at 2 eps_0) and ``orca`` (fleet.sim.orca). A run is
judged on its executed motion: ``breach``, else ``contact``, else ``deadlock`` (no car
still out moved DEADLOCK_MOVE_M in the last DEADLOCK_WINDOW_S), else ``timeout``, else
``success``. Each run goes to the journal as it ends, so a stopped bank carries on;
``--fresh K`` adds random fields nobody tuned on, ``--recheck K`` reruns K journal entries,
``--set`` changes a config value, ``--vehicle car`` drives a fleet of car-like cars. docs/design/experiments.md, "The scenario bank".
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import secrets
import sys
import time
import tomllib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ....agent.config import ConfigError, Scenario, VehicleConfig
from ....agent.config.running import STEERING
from ....agent.scenario_files import read_source, scenario_from_dict
from ...program import command_parser, configured
from ...sim.in_process import simulate
from ...sim.run_record import RunRecord, fingerprint, motion_summary
from .. import run_environment
from ..cluster import Cluster, ClusterError, cluster_at, cluster_option
from ..paper import BELIEVING, NO_TRUST, Progress, _sdf
from ..run_environment import code_version
from ..workers import parallel
from . import recheck as bank_recheck

BANK = ("circle-4", "circle-8", "circle-16", "circle-obstacles-4", "circle-obstacles-8", "corridor-4",
        "bottleneck-4", "t-junction-6", "warehouse-8", "random-field-6-a", "random-field-6-b")
"""The shipped scenes of the bank (deploy/scenarios; each file says how it was generated)."""
FRESH_KIND = "random-field"
DEADLOCK_WINDOW_S = 5.0
DEADLOCK_MOVE_M = 0.05


@dataclass(frozen=True)
class Method:
    label: str
    description: str
    overrides: dict = field(default_factory=dict)
    """Config changes, as a scenario file's tables: {section: {key: value}}."""
    orca: bool = False


METHODS = {
    "full": Method("full pipeline", "every trust factor on, the pipeline as shipped"),
    "fixed": Method("no trust, eps_0", "no trust factors; eps_0 from every peer",
                    {"planner": NO_TRUST, "trust": BELIEVING}),
    "wide": Method("no trust, 2 eps_0", "no trust factors; 2 eps_0 from every peer",
                   {"planner": NO_TRUST, "trust": BELIEVING | {"epsilon_gain_fixed": 2.0}}),
    "orca": Method("ORCA", "ORCA (pyrvo), perfect state, no messages", orca=True),
}


# --- scenes and their variants -----------------------------------------------------------------


def scene_data(source: str | Path) -> tuple[dict, str]:
    """A scene file's tables and its first comment line (what it is, how it was made)."""
    text, label = read_source(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{label}: not valid TOML: {exc}") from None
    first = text.splitlines()[0] if text else ""
    return data, first.lstrip("# ").strip() if first.startswith("#") else ""


def variant(data: dict, *changes: dict) -> Scenario:
    """The scene with every table of ``changes`` merged in, validated."""
    merged = copy.deepcopy(data)
    for change in changes:
        for section, values in change.items():
            merged.setdefault(section, {}).update(values)
    return scenario_from_dict(merged)


def parse_settings(settings: list[str]) -> dict:
    """``SECTION.KEY=VALUE`` (VALUE in TOML: 0.5, true, "text", [1, 2]) -> {section: {key: value}}."""
    out: dict = {}
    for setting in settings:
        name, sep, value = setting.partition("=")
        section, dot, key = name.strip().partition(".")
        if not (sep and dot and section and key):
            raise ConfigError(f"--set {setting!r}: expected SECTION.KEY=VALUE")
        try:
            parsed = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            raise ConfigError(f"--set {setting!r}: {value!r} is not a TOML value") from None
        out.setdefault(section, {})[key] = parsed
    return out


# --- one run ---------------------------------------------------------------------------------


def run_case(scene: str, scenario: Scenario, method: str, seed: int) -> dict:
    """Simulate one seed of one scene with one method and judge it."""
    started, cpu = time.perf_counter(), time.process_time()
    sdf = _sdf(scenario.world)
    if METHODS[method].orca:
        from ...sim.orca import simulate_orca
        record = simulate_orca(scenario, seed, sdf)
    else:
        record = simulate(scenario, seed, sdf=sdf, record_trust=False)
    return judge(scene, method, scenario, record, sdf) | {"wall_s": round(time.perf_counter() - started, 2),
                                                          "cpu_s": round(time.process_time() - cpu, 2)}


def judge(scene: str, method: str, scenario: Scenario, record: RunRecord, sdf) -> dict:
    motion = motion_summary(scenario, record, sdf)
    n = len(record.car_ids)
    clearance = np.array(motion["min_clearance"], dtype=float)
    np.fill_diagonal(clearance, np.inf)
    arrived = record.arrived_at
    if motion["breaches"]:
        outcome = "breach"
    elif motion["obstacle_min_clearance"] < 0.0:
        outcome = "contact"
    elif all(a is not None for a in arrived):
        outcome = "success"
    else:
        outcome = "deadlock" if stuck(record) else "timeout"
    replans = np.concatenate([np.asarray(r, dtype=float) for r in record.replan_ms]) if record.replan_ms else np.zeros(0)
    tracking = np.concatenate(record.tracking_error) if record.tracking_error else np.zeros(0)
    counters: dict[str, int] = {}
    for car in record.counters:
        for key, value in car.items():
            counters[key] = counters.get(key, 0) + int(value)
    return {
        "scene": scene, "method": method, "seed": record.seed, "cars": n, "outcome": outcome,
        "least_clearance_m": round(float(clearance.min()), 4),
        "obstacle_min_clearance_m": motion["obstacle_min_clearance"],
        "breaches": motion["breaches"],
        "arrived": sum(a is not None for a in arrived),
        "makespan_s": motion["makespan_s"],
        "flowtime_s": round(sum(arrived), 3) if all(a is not None for a in arrived) else None,
        "replan_ms_median": round(float(np.median(replans)), 3) if replans.size else None,
        "replan_ms_p95": round(float(np.percentile(replans, 95)), 3) if replans.size else None,
        "tracking_error_p95_m": round(float(np.percentile(tracking, 95)), 4) if tracking.size else None,
        "counters": counters,
    }


def stuck(record: RunRecord) -> bool:
    """No car still out moved more than DEADLOCK_MOVE_M in the run's last DEADLOCK_WINDOW_S."""
    out = [i for i, a in enumerate(record.arrived_at) if a is None]
    window = record.times >= record.times[-1] - DEADLOCK_WINDOW_S
    positions = record.states[window][:, out, :2]
    spread = np.linalg.norm(positions - positions[-1:], axis=-1).max(axis=0)
    return bool(np.all(spread <= DEADLOCK_MOVE_M))


def _case(args: tuple[str, Scenario, str, int]) -> dict:
    """One run, and the digest of the environment it ran in (a cluster's worker may be
    another machine than the one that journals it)."""
    return run_case(*args) | {"env": run_environment.digest(run_environment.environment())}


# --- the whole bank ----------------------------------------------------------------------------


def run_bank(scenes: dict[str, tuple[dict, str]], methods: list[str], seeds: dict[str, list[int]], jobs: int,
             settings: dict, groups: dict[str, str], journal: Path, run_missing: bool = True,
             cluster: Cluster | None = None) -> list[dict]:
    """Every (scene, method, seed); ``groups`` says which row (bank or fresh) a scene joins;
    the runs go to ``cluster`` when given, else to ``jobs`` local worker processes.

    Each finished run is appended to ``journal`` (JSON lines) at once, with the commit it
    ran on (:func:`code_version`) and its environment; a run already there
    for the same scene config, method and seed is not run again, so a long bank that was
    stopped carries on where it stopped when started again with the same --out. With
    ``run_missing`` off, nothing runs: the journal's runs of the selection, and a line
    saying how many are missing, by method."""
    done = {}
    if journal.exists():
        for line in journal.read_text().splitlines():
            run = json.loads(line)
            done[(run["fingerprint"], run["method"], run["seed"])] = run
    tasks, runs = [], []
    for scene, (data, _) in scenes.items():
        for method in methods:
            scenario = variant(data, METHODS[method].overrides, settings)
            mark = fingerprint(scenario)
            for seed in seeds[scene]:
                if (mark, method, seed) in done:
                    runs.append(done[(mark, method, seed)] | {"scene": scene, "group": groups[scene]})
                else:
                    tasks.append((scene, scenario, method, seed))
    if not run_missing:
        missing = Counter(method for _, _, method, _ in tasks)
        print(f"{len(runs)} runs of the selection in {journal}; not in it (none run now): "
              + (", ".join(f"{method} {n}" for method, n in missing.items()) or "none"), file=sys.stderr)
        tasks = []
    elif runs:
        print(f"{len(runs)} runs already in {journal}, {len(tasks)} to go", file=sys.stderr)
    if tasks:  # nothing to run (a whole journal, or --report-only): no pool, and the journal untouched
        tasks.sort(key=lambda task: -len(task[1].cars))  # the big scenes first: the pool ends together
        progress = Progress("bank", len(tasks))
        code = code_version()
        envs = cluster.environments() if cluster else {run_environment.digest(run_environment.environment())}
        others = Counter(run.get("env", "not recorded") for run in runs if run.get("env") not in envs)
        if others:  # carrying on elsewhere: the new runs are runs of their seeds, not replays of the old
            print("note: the journal's runs of this selection ran in other environments ("
                  + ", ".join(f"{name}: {n}" for name, n in others.items()) + f"), these run in "
                  f"{', '.join(sorted(envs))} (fleet.experiments.run_environment): a seed rerun here need not "
                  "repeat an entry", file=sys.stderr)
        with journal.open("a") as log:
            for task, run in parallel(_case, tasks, jobs, ordered=False, cluster=cluster):
                env = run.pop("env")  # the entry's bookkeeping keeps its order: group, fingerprint, code, env
                run["group"] = groups[run["scene"]]
                run["fingerprint"] = fingerprint(task[1])
                run["code"] = code
                run["env"] = env
                log.write(json.dumps(run) + "\n")
                log.flush()
                runs.append(run)
                progress.step(f"{run['scene']} {run['method']} seed {run['seed']}: {run['outcome']}, "
                              f"least clearance {run['least_clearance_m']:.3f} m, {run['wall_s']:.1f} s")
        progress.done()
    runs.sort(key=lambda r: (r["group"] != "bank", list(scenes).index(r["scene"]), list(METHODS).index(r["method"]),
                             r["seed"]))
    return runs


def recheck(scenes: dict[str, tuple[dict, str]], methods: list[str], seeds: dict[str, list[int]], settings: dict,
            groups: dict[str, str], out: Path, count: int, jobs: int, cluster: Cluster | None = None) -> int:
    """Rerun ``count`` of the journal's runs of the selection here (or on ``cluster``); each compared with its
    entry (fleet.experiments.bank.recheck), the lot written to OUT/recheck.json. 0 when every rerun is
    its entry to the last digit, 1 when one is not, 2 when the journal has none."""
    runs = run_bank(scenes, methods, seeds, jobs, settings, groups, out / "runs.jsonl", run_missing=False)
    if not runs:
        print(f"trustfg experiment bank: no run of this selection in {out / 'runs.jsonl'} to recheck", file=sys.stderr)
        return 2
    chosen = {(r["scene"], r["method"], r["seed"]): r for r in bank_recheck.pick(runs, count)}
    tasks = [(scene, variant(scenes[scene][0], METHODS[method].overrides, settings), method, seed)
             for scene, method, seed in chosen]
    env = run_environment.environment()
    here = run_environment.digest(env)
    where = f"on {cluster.address} (code {code_version()}, envs {', '.join(sorted(cluster.environments()))})" \
        if cluster else f"here (code {code_version()}, env {here})"
    print(f"rerunning {len(tasks)} of the journal's {len(runs)} runs {where}", file=sys.stderr)
    progress = Progress("recheck", len(tasks))
    rechecked = []
    for task, rerun in parallel(_case, tasks, jobs, ordered=False, cluster=cluster):
        entry = chosen[(task[0], task[2], task[3])]
        changed = bank_recheck.differences(entry, rerun)
        rechecked.append({"scene": task[0], "method": task[2], "seed": task[3], "same": not changed,
                          "differences": changed, "journal": {f: entry.get(f) for f in ("code", "env", *bank_recheck.FIELDS)},
                          "rerun": {f: rerun.get(f) for f in ("env", *bank_recheck.FIELDS)}})
        progress.step(bank_recheck.line(entry, rerun, rerun["env"]))
        if changed and progress.tty:
            print(file=sys.stderr)  # a rerun that differs keeps its line
    progress.done()
    same = sum(r["same"] for r in rechecked)
    (out / "recheck.json").write_text(json.dumps({"code": code_version(), "env": here, "environment": env,
                                                  "same": same, "rechecked": rechecked}, indent=1))
    print(f"{same} of {len(rechecked)} reruns the same as their journal entries to the last digit; "
          f"wrote {(out / 'recheck.json').resolve()}")
    return 0 if same == len(rechecked) else 1


def machine() -> dict:
    return {"cpus": os.cpu_count(), "cpu": run_environment.cpu_model(), "platform": platform.platform(),
            "python": platform.python_version()}


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.recheck < 0:
        parser.error("--recheck must be at least 0")
    if args.seeds < 1 or args.fresh < 0 or args.fresh_seeds < 1:
        parser.error("--seeds and --fresh-seeds must be at least 1, --fresh at least 0")
    if "orca" in args.methods:
        from ...sim.orca import MissingLibrary, _pyrvo
        try:
            _pyrvo()
        except MissingLibrary as exc:
            print(f"trustfg experiment bank: {exc}", file=sys.stderr)
            return 2
    out = args.out or Path("runs") / time.strftime("bank-%Y%m%d-%H%M%S")
    settings = configured("trustfg experiment bank", lambda: with_vehicle(parse_settings(args.set), args))
    scenes, groups, seeds = _chosen_scenes(args, settings)
    _add_fresh_scenes(parser, args, out, scenes, groups, seeds)
    if args.recheck:
        try:
            with cluster_at(args.cluster, args.jobs) as cluster:
                return recheck(scenes, args.methods, seeds, settings, groups, out, args.recheck, args.jobs, cluster)
        except KeyboardInterrupt:
            print("\nstopped; nothing was written", file=sys.stderr)
            return 130
        except ClusterError as exc:
            print(f"trustfg experiment bank: {exc}", file=sys.stderr)
            return 2
    started = time.perf_counter()
    if not args.report_only:  # a report of a folder that holds no journal leaves nothing behind
        out.mkdir(parents=True, exist_ok=True)
    try:
        with cluster_at(args.cluster, args.jobs) as cluster:  # connected when a run is to go to it
            runs = run_bank(scenes, args.methods, seeds, args.jobs, settings, groups, out / "runs.jsonl",
                            run_missing=not args.report_only, cluster=cluster)
    except KeyboardInterrupt:
        print(f"\nstopped; every finished run is in {out / 'runs.jsonl'}: the same command carries on",
              file=sys.stderr)
        return 130
    except ClusterError as exc:
        kept = f"; every finished run is in {out / 'runs.jsonl'}" if (out / "runs.jsonl").exists() else ""
        print(f"trustfg experiment bank: {exc}{kept}", file=sys.stderr)
        return 2
    if not runs:
        print(f"trustfg experiment bank: no run of this selection in {out / 'runs.jsonl'}", file=sys.stderr)
        return 2
    report = _report_of(args, argv, runs, scenes, groups, seeds, settings, started)
    _write_report(report, out, figures=not args.no_figures)
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = command_parser("trustfg experiment bank", __doc__)
    parser.add_argument("--scenes", nargs="+", default=list(BANK), metavar="SCENE",
                        help="scene names or files (default: the bank, " + " ".join(BANK) + ")")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--seeds", type=int, default=100, help="seeds per scene (default 100)")
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=list(METHODS),
                        help="what drives the cars (default: all of " + ", ".join(METHODS) + ")")
    parser.add_argument("--fresh", type=int, default=0,
                        help="add this many random-field scenes from generator seeds drawn now (default 0)")
    parser.add_argument("--fresh-cars", type=int, default=6, help="cars in each fresh scene (default 6)")
    parser.add_argument("--fresh-seeds", type=int, default=5, help="seeds per fresh scene (default 5)")
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="change a config value of every scene and method (repeatable; TOML values)")
    parser.add_argument("--vehicle", choices=STEERING, default=None,
                        help="what steers every car: 'in-place' (turns on the spot) or 'car' (front wheels, "
                             "--min-turn-radius; default: as each scene says)")
    parser.add_argument("--min-turn-radius", type=float, default=None, metavar="M",
                        help="with --vehicle car: the cars' minimum turning radius, m (default: the config's, "
                             f"{VehicleConfig.min_turn_radius_m})")
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                        help="parallel runs (default: one per core)")
    cluster_option(parser)
    parser.add_argument("--out", type=Path, default=None,
                        help="output folder (default runs/bank-<time>); an existing one carries on where it stopped")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figure")
    parser.add_argument("--report-only", action="store_true",
                        help="run nothing: the table and figure of the runs of --out's journal that match the "
                             "selection (how many are missing is said)")
    parser.add_argument("--recheck", type=int, default=0, metavar="K",
                        help="run nothing new: rerun K of the journal's runs of the selection (drawn with a fixed "
                             "seed) and say which came out the same; exit 1 when one did not")
    return parser


def with_vehicle(settings: dict, args: argparse.Namespace) -> dict:
    """``settings`` with --vehicle and --min-turn-radius in its [vehicle] table."""
    vehicle = {}
    if args.vehicle is not None:
        vehicle["steering"] = args.vehicle
    if args.min_turn_radius is not None:
        if args.vehicle != "car":
            raise ConfigError("--min-turn-radius: only with --vehicle car")
        vehicle["min_turn_radius_m"] = args.min_turn_radius
    if vehicle:
        settings.setdefault("vehicle", {}).update(vehicle)
    return settings


def _chosen_scenes(args: argparse.Namespace, settings: dict) -> tuple[dict, dict, dict]:
    """The --scenes (data and note by name), their group ("bank") and seeds; every
    method's variant of each is made once here, so that a bad --set fails now."""
    scenes = {}
    for source in args.scenes:
        data, note = configured("trustfg experiment bank", lambda: scene_data(source))
        scenes[str(data.get("name") or Path(source).stem)] = (data, note)
    for method in args.methods:  # a bad --set fails here, once, not in every worker
        for data, _ in scenes.values():
            configured("trustfg experiment bank", lambda: variant(data, METHODS[method].overrides, settings))
    groups = {name: "bank" for name in scenes}
    seeds = {name: list(range(args.seed, args.seed + args.seeds)) for name in scenes}
    return scenes, groups, seeds


def _add_fresh_scenes(parser: argparse.ArgumentParser, args: argparse.Namespace, out: Path,
                      scenes: dict, groups: dict, seeds: dict) -> None:
    """With --fresh, its scenes added to ``scenes`` (group "fresh", --fresh-seeds seeds
    each): those of out/fresh when a stopped bank carries on, else made now from
    generator seeds drawn from the operating system's entropy and saved there."""
    if not args.fresh:
        return
    fresh = out / "fresh"
    if fresh.is_dir() and any(fresh.glob("*.toml")):
        print(f"reusing the fresh scenes in {fresh}", file=sys.stderr)  # a stopped bank carries on
        paths = sorted(fresh.glob("*.toml"))
    elif args.report_only or args.recheck:
        parser.error(f"--report-only or --recheck with --fresh: no fresh scenes in {fresh} to report on")
    else:
        from ...sim.scene_gen import generate, scene_file_text
        fresh_seeds = [secrets.randbelow(2**31) for _ in range(args.fresh)]
        print(f"fresh {FRESH_KIND} scenes ({args.fresh_cars} cars) from generator seeds {fresh_seeds}", file=sys.stderr)
        fresh.mkdir(parents=True, exist_ok=True)
        paths = []
        for seed in fresh_seeds:
            name = f"{FRESH_KIND}-{args.fresh_cars}-s{seed}"
            scenario, text = configured("trustfg experiment bank",
                                        lambda: generate(FRESH_KIND, args.fresh_cars, seed, name))
            paths.append(fresh / f"{name}.toml")
            paths[-1].write_text(scene_file_text(scenario, FRESH_KIND, args.fresh_cars, seed, text))
    for path in paths:
        data, note = scene_data(path)
        scenes[data["name"]] = (data, note)
        groups[data["name"]] = "fresh"
        seeds[data["name"]] = list(range(args.seed, args.seed + args.fresh_seeds))


def _report_of(args: argparse.Namespace, argv: list[str] | None, runs: list[dict], scenes: dict, groups: dict,
               seeds: dict, settings: dict, started: float) -> dict:
    """bank.json: the command, machine and environment, the selection, the summary
    (fleet.experiments.bank.report) and every run."""
    from . import report as bank_report
    return {
        "experiment": "bank",
        "command": "trustfg experiment bank " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": machine(),
        "environment": run_environment.environment(),
        "wall_time_s": None if args.report_only else round(time.perf_counter() - started, 1),
        "cpu_time_s": round(sum(r.get("cpu_s", 0.0) for r in runs), 1),
        "code": dict(Counter(r.get("code", "not recorded") for r in runs)),
        "env": dict(Counter(r.get("env", "not recorded") for r in runs)),
        "methods": {m: {"label": METHODS[m].label, "description": METHODS[m].description} for m in args.methods},
        "scenes": {name: {"group": groups[name], "about": note, "seeds": seeds[name]}
                   for name, (_, note) in scenes.items()},
        "fresh_generator_seeds": [int(n.rsplit("-s", 1)[1]) for n, g in groups.items() if g == "fresh"],
        "settings": settings,
        "summary": bank_report.summarise(runs),
        "runs": runs,
    }


def _write_report(report: dict, out: Path, figures: bool) -> None:
    """out/bank.json, out/bank.md (the table, also printed) and, with ``figures``, out/bank.png."""
    from . import report as bank_report
    out.mkdir(parents=True, exist_ok=True)
    (out / "bank.json").write_text(json.dumps(report, indent=1))
    table = bank_report.markdown(report)
    (out / "bank.md").write_text(table)
    if figures:
        bank_report.figure(report, out / "bank.png")
    print(table)
    print(f"wrote {out.resolve()}")
