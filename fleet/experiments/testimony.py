"""``trustfg experiment testimony``: what testimonies buy a car that sees only its neighbours.

    trustfg experiment testimony [--seeds 50] [--seed 0] [--range 1.5]
                                 [--scenes corridor-4 circle-8] [--jobs J] [--cluster ADDRESS] [--out DIR]

Per scene and seed the in-process fleet runs twice with a sensing range
(``sensing.range_m``), car 1 lying as the paper's liar (40 % of its plans displaced, its
testimonies swapped): testimonies on and off (``trust.testimonies``), the same seeds. For
every honest car that does not see the liar at the start: when it first sees it, how long
before that it already distrusted it (transparency trust below a stranger's), its trust
in it then, and the distance it kept from the liar and from its honest peers while they
were out of its sight; per run, the least honest-liar clearance and the makespan.
Writes DIR/testimony/metrics.json and table.md. docs/design/experiments.md, "Testimonies".
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from ...agent.config import Scenario
from ...agent.scenario_files import load_scenario
from ...agent.sight import sight_matrix, unseen_epsilon
from ...agent.trust import expected
from ...agent.world import build_sdf
from ..program import command_parser, configured
from ..sim.run_record import RunRecord
from ..sim.trust_record import positions_at
from . import stats
from .cluster import ClusterError, cluster_at
from .paper import Progress, run_one, study_folder, study_options, trust_on, with_liar, write_study
from .workers import parallel

RANGE_M = 1.5
SCENES = ("corridor-4", "circle-8")
ARMS = ("on", "off")
SETTLED_IN_SIGHT_S = 3.0
"""An honest car's trust in an honest peer it has seen this long is held to
stats.FALSE_POSITIVE_TRUST (docs/design/trust.md, "Limited sight")."""


def with_range(scenario: Scenario, range_m: float) -> Scenario:
    """``scenario`` with every car seeing its peers within ``range_m`` only."""
    return dataclasses.replace(scenario, sensing=dataclasses.replace(scenario.sensing, range_m=range_m))


def prepared(scene: str, range_m: float) -> Scenario:
    """A scene with car 1 the paper's liar and every car seeing ``range_m``, validated."""
    scenario = with_range(with_liar(load_scenario(scene)), range_m)
    scenario.validate()
    return scenario


def with_testimonies(scenario: Scenario, on: bool) -> Scenario:
    return dataclasses.replace(scenario, trust=dataclasses.replace(scenario.trust, testimonies=on))


def sight_over(scenario: Scenario, record: RunRecord) -> np.ndarray:
    """seen[k, a, b]: car a saw car b at ``record.trust_times[k]`` (the cars stand at their
    starts before the go), by the in-process fleet's own rule (agent.sight)."""
    sdf = build_sdf(scenario.world) if scenario.sensing.line_of_sight else None
    ranges = [scenario.sensing_range(c) for c in scenario.cars]
    where = [positions_at(record.times, record.states[:, i, :2])(record.trust_times) for i in range(len(ranges))]
    return np.stack([sight_matrix(np.array([w[k] for w in where]), ranges, sdf)
                     for k in range(len(record.trust_times))])


def _runs_of(flags: np.ndarray) -> np.ndarray:
    """For each sample, how many samples in a row up to it (inclusive) were True."""
    out = np.zeros(len(flags), dtype=int)
    count = 0
    for k, flag in enumerate(flags):
        count = count + 1 if flag else 0
        out[k] = count
    return out


def sight_summary(scenario: Scenario, record: RunRecord) -> dict:
    """RUN keys of a run with limited sight: ``honest_trust_min_in_sight`` (the least trust
    of an honest car in an honest peer it had seen for SETTLED_IN_SIGHT_S or longer; None:
    no such moment), ``honest_low_in_sight_s`` (the longest such time, per pair, below
    stats.FALSE_POSITIVE_TRUST) and ``liar_cleared_unseen`` (pairs in which an honest car
    that had seen a liar lie -- distrusted it while it saw it -- later trusted it as a
    stranger or more while it did not see it)."""
    seen = sight_over(scenario, record)
    period = float(np.median(np.diff(record.trust_times))) if len(record.trust_times) > 1 else 0.1
    settled = int(round(SETTLED_IN_SIGHT_S / period))
    liars = {record.car_ids.index(c) for c in scenario.liars}
    honest = [i for i in range(len(record.car_ids)) if i not in liars]
    stranger = float(expected(scenario.trust.prior_alpha, scenario.trust.prior_beta))
    lows, least, cleared = [0.0], [], 0
    for a in honest:
        for b in honest:
            if a == b:
                continue
            steady = _runs_of(seen[:, a, b]) > settled
            if steady.any():
                trust = record.trust[steady, a, b]
                least.append(float(trust.min()))
                lows.append(float(np.sum(trust < stats.FALSE_POSITIVE_TRUST)) * period)
        for liar in liars:
            caught = np.flatnonzero(seen[:, a, liar] & (record.transparency[:, a, liar] < stranger))
            if len(caught):
                later = slice(caught[0], None)
                cleared += bool(np.any(~seen[later, a, liar] & (record.transparency[later, a, liar] >= stranger)))
    return {"sight_range_m": scenario.sensing.range_m,
            "honest_trust_min_in_sight": round(min(least), 4) if least else None,
            "honest_low_in_sight_s": round(max(lows), 2), "liar_cleared_unseen": cleared}


def observers(scenario: Scenario, record: RunRecord) -> list[dict]:
    """Per honest car that does not see the liar at the start: when it first saw it
    (``first_sight_s``, None: never), how long before that it already distrusted it
    (``ahead_s``: the distrust that lasted up to first sight; negative: distrusted only
    after, None: not in the run), its trust in the liar at first sight, and the mean
    distance it planned to keep from the liar and from its honest peers while each was
    out of its sight (the planner's rule: the epsilon trust gives, at least unseen_epsilon)."""
    seen = sight_over(scenario, record)
    times = record.trust_times
    liar = record.car_ids.index(scenario.liars[0])
    honest = [i for i in range(len(record.car_ids)) if i != liar]
    stranger = float(expected(scenario.trust.prior_alpha, scenario.trust.prior_beta))
    radius = {i: c.radius_m for i, c in enumerate(scenario.cars)}
    out = []
    for a in honest:
        if seen[0, a, liar]:
            continue
        sighted = np.flatnonzero(seen[:, a, liar])
        distrusted = record.transparency[:, a, liar] < stranger
        first = int(sighted[0]) if len(sighted) else None
        ahead = None
        if first is not None and distrusted[first]:
            start = first
            while start > 0 and distrusted[start - 1]:
                start -= 1
            ahead = float(times[first] - times[start])
        elif first is not None and distrusted[first:].any():
            ahead = -float(times[first + int(np.argmax(distrusted[first:]))] - times[first])

        def unseen_epsilon_of(b: int, until: int | None) -> float | None:
            hidden = ~seen[:until, a, b]
            if not hidden.any():
                return None
            floor = unseen_epsilon(scenario.safety.epsilon_0(radius[a], radius[b]), scenario.trust)
            return float(np.mean(np.maximum(record.epsilon[:until, a, b][hidden], floor)))

        peers = [e for b in honest if b != a and (e := unseen_epsilon_of(b, first)) is not None]
        out.append({"observer": record.car_ids[a],
                    "first_sight_s": None if first is None else round(float(times[first]), 2),
                    "ahead_s": None if ahead is None else round(ahead, 2),
                    "trust_at_first_sight": None if first is None else round(float(record.trust[first, a, liar]), 4),
                    "liar_epsilon_unseen_m": None if (e := unseen_epsilon_of(liar, first)) is None else round(e, 4),
                    "honest_epsilon_unseen_m": round(float(np.mean(peers)), 4) if peers else None})
    return out


def run_summary(task: tuple) -> dict:
    """One seed of one arm: the RUN dict, its sight keys and its observers."""
    *_, scenario, seed = task
    run, record = run_one(scenario, seed)
    return run | sight_summary(scenario, record) | {"observers": observers(scenario, record)}


def cell(runs: list[dict]) -> dict:
    """The table's numbers for one scene and arm."""
    seen = [o for r in runs for o in r["observers"] if o["first_sight_s"] is not None]
    return stats.cell(runs) | {
        "all_arrived_rate": stats.rate([all(r["reached_goal"]) for r in runs]),
        "observers": sum(len(r["observers"]) for r in runs), "observers_meeting_liar": len(seen),
        "ahead_s": stats.estimate([o["ahead_s"] for o in seen]),
        "never_distrusted": sum(1 for o in seen if o["ahead_s"] is None),
        "distrusted_before_sight_rate": stats.rate([(o["ahead_s"] or 0.0) > 0.0 for o in seen]),
        "trust_at_first_sight": stats.estimate([o["trust_at_first_sight"] for o in seen]),
        "liar_epsilon_unseen_m": stats.estimate([o["liar_epsilon_unseen_m"] for o in seen]),
        "honest_epsilon_unseen_m": stats.estimate([o["honest_epsilon_unseen_m"] for r in runs for o in r["observers"]]),
        "honest_low_in_sight_s_max": max(r["honest_low_in_sight_s"] for r in runs),
        "liar_cleared_unseen": sum(r["liar_cleared_unseen"] for r in runs),
    }


def paired(on: list[dict], off: list[dict], key, statistic=np.median) -> dict | None:
    """The median (or ``statistic``) over seeds of on - off of a RUN key (or of ``key(run)``),
    with its interval (the same seeds)."""
    value = key if callable(key) else (lambda run: run.get(key))
    by_seed = {r["seed"]: value(r) for r in off}
    return stats.estimate([value(r) - by_seed[r["seed"]] for r in on
                           if value(r) is not None and by_seed.get(r["seed"]) is not None], statistic)


def all_arrived(run: dict) -> float:
    """1.0 when every car of a RUN reached its goal, else 0.0 (a rate's sample)."""
    return float(all(run["reached_goal"]))


def summarise(by_arm: dict[str, list[dict]]) -> dict:
    """The cells of one scene, and the paired differences on - off."""
    return {arm: cell(by_arm[arm]) for arm in ARMS} | {
        "all_arrived_on_minus_off": paired(by_arm["on"], by_arm["off"], all_arrived, np.mean),
        "makespan_on_minus_off": paired(by_arm["on"], by_arm["off"], "makespan_s"),
        "clearance_on_minus_off": paired(by_arm["on"], by_arm["off"], "liar_min_clearance")}


def table(summary: dict, range_m: float, seeds: int) -> str:
    rows = []
    for scene, by_arm in summary.items():
        for arm in ARMS:
            c = by_arm[arm]
            rows.append([scene, arm, f"{c['all_arrived']}/{c['runs']} ({stats.show(c['all_arrived_rate'], 0, True)})",
                         f"{c['observers_meeting_liar']}/{c['observers']}",
                         stats.show(c["ahead_s"], 1), stats.show(c["distrusted_before_sight_rate"], 0, True),
                         stats.show(c["trust_at_first_sight"], 2), stats.show(c["liar_epsilon_unseen_m"], 2),
                         stats.show(c["honest_epsilon_unseen_m"], 2),
                         f"{c['breach_seeds']}/{c['runs']}", f"{c['min_clearance_m']:.3f}",
                         stats.show(c["median_clearance_m"], 3), stats.show(c["makespan_s"], 1)])
        rows.append([scene, "on - off", stats.show(by_arm["all_arrived_on_minus_off"], 0, True), "", "", "", "", "", "",
                     "", "", stats.show(by_arm["clearance_on_minus_off"], 3), stats.show(by_arm["makespan_on_minus_off"], 1)])
    return stats.markdown(
        f"sensing range {range_m:g} m, car 1 the paper's liar, {seeds} seeds per cell",
        ["scene", "testimonies", "every car at its goal", "observers meeting the liar", "distrusted it ahead of first sight (s), median",
         "... share", "trust in it at first sight", "its epsilon unseen (m)", "honest peers' epsilon unseen (m)",
         "honest-liar breaches", "least clearance (m)", "median least clearance (m)", "makespan (s), median"], rows)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg experiment testimony", __doc__)
    study_options(parser, seeds=50)
    parser.add_argument("--range", type=float, default=RANGE_M, dest="range_m", metavar="M",
                        help=f"every car's sensing range, m (default {RANGE_M})")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES), help=f"scenes (default: {' '.join(SCENES)})")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    scenes = {scene: configured("trustfg experiment testimony", lambda: prepared(scene, args.range_m))
              for scene in args.scenes}
    out = study_folder(args.out, "testimony")
    started = time.perf_counter()
    seeds = list(range(args.seed, args.seed + args.seeds))
    tasks = [(scene, arm, trust_on(with_testimonies(base, arm == "on")), seed)
             for scene, base in scenes.items() for arm in ARMS for seed in seeds]
    results: dict = {}
    progress = Progress("testimony", len(tasks))
    try:
        with cluster_at(args.cluster, args.jobs) as cluster:
            for (scene, arm, _, seed), run in parallel(run_summary, tasks, args.jobs, cluster=cluster):
                results.setdefault(scene, {}).setdefault(arm, []).append(run)
                progress.step(f"{scene} testimonies {arm} seed {seed}: least honest-liar clearance "
                              f"{run['liar_min_clearance']:.3f} m")
    except ClusterError as exc:
        print(f"trustfg experiment testimony: {exc}", file=sys.stderr)
        return 2
    progress.done()
    summary = {}
    for scene, by_arm in results.items():
        for runs in by_arm.values():
            runs.sort(key=lambda r: r["seed"])
        summary[scene] = summarise(by_arm)
    report = {"experiment": "testimony", "range_m": args.range_m, "seeds": seeds, "scenes": list(scenes),
              "summary": summary, "runs": results, "wall_time_s": round(time.perf_counter() - started, 1)}
    write_study(out, report, table(summary, args.range_m, len(seeds)))
    return 0
