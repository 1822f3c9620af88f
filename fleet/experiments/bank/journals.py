"""One table and figure from the bank's journals as they were recorded, several commits side by side.

    trustfg experiment bank-journals FILE[:METHOD,...] [FILE[:METHOD,...] ...]
                                     [--scenes NAME ...] [--seed S] [--seeds K] [--out DIR] [--no-figures]

``trustfg experiment bank --report-only`` reports the runs of one journal whose
configuration this commit would run (fleet.sim.run_record.fingerprint). This command
reports journal entries as they stand, naming each run's commit, so that runs of several
commits stand side by side (the shipped pipeline from its journal, the baselines from
theirs): from every FILE the entries of the METHODs named (all without ``:``), for the
bank scenes of ``--scenes`` and seeds ``--seed`` .. ``--seed + --seeds - 1``, and every
fresh scene's entries. Nothing is run. A run found in two journals is counted once when
both entries record the same run (fleet.experiments.bank.recheck.FIELDS), else refused.
"""

from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from ....agent.config import ConfigError
from ...program import command_parser, configured
from .. import run_environment
from . import recheck as bank_recheck
from . import report as bank_report
from .runner import BANK, METHODS, machine, scene_data

RUN_KEYS = ("scene", "method", "seed", "outcome")
"""What every run of a journal names."""


def parse_take(spec: str) -> tuple[Path, list[str]]:
    """``FILE[:METHOD,...]`` -> (FILE, methods); no methods: every method."""
    name, sep, listed = spec.rpartition(":") if ":" in spec else (spec, "", "")
    methods = [m.strip() for m in listed.split(",") if m.strip()] if sep else list(METHODS)
    unknown = [m for m in methods if m not in METHODS]
    if unknown or (sep and not methods):
        raise ConfigError(f"{spec!r}: methods are a comma list of {', '.join(METHODS)}"
                          + (f" (not {', '.join(unknown)})" if unknown else ""))
    return Path(name), methods


def read_journal(path: Path) -> list[dict]:
    """A journal's entries (JSON lines); a line that is not one is an error naming it."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the journal: {exc.strerror or exc}") from None
    entries = []
    for number, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
            if not isinstance(entry, dict):
                raise TypeError(f"a JSON {type(entry).__name__}, not an object")
            missing = [key for key in RUN_KEYS if key not in entry]
            if missing:
                raise KeyError(", ".join(missing))
        except (json.JSONDecodeError, TypeError, KeyError) as exc:
            raise ConfigError(f"{path}:{number}: not a bank run ({type(exc).__name__}: {exc})") from None
        entries.append(entry)
    return entries


def gather(journals: list[tuple[str, list[dict], list[str]]], scenes: list[str],
           seeds: range) -> tuple[list[dict], int]:
    """The selected runs of every journal (module doc), and how many were found twice.
    ``journals``: (name, entries, methods) per FILE."""
    chosen: dict[tuple, tuple[str, dict]] = {}
    repeats = 0
    for name, entries, methods in journals:
        for entry in entries:
            group = entry.get("group", "bank")
            if entry["method"] not in methods or (group == "bank" and (entry["scene"] not in scenes
                                                                        or entry["seed"] not in seeds)):
                continue
            key = (group, entry["scene"], entry["method"], entry["seed"])
            if key in chosen:
                first, earlier = chosen[key]
                changed = bank_recheck.differences(earlier, entry)
                if changed:
                    raise ConfigError(f"{key[1]} {key[2]} seed {key[3]} is in {first} and {name} as different "
                                      f"runs ({', '.join(changed)}): name the method in one of them only")
                repeats += 1
                continue
            chosen[key] = (name, entry | {"group": group})
    runs = [entry for _, entry in chosen.values()]
    order = {scene: i for i, scene in enumerate(scenes)}
    runs.sort(key=lambda r: (r["group"] != "bank", order.get(r["scene"], len(order)), r["scene"],
                             list(METHODS).index(r["method"]), r["seed"]))
    return runs, repeats


def report(runs: list[dict], command: str, journals: dict[str, list[str]]) -> dict:
    """The report fleet.experiments.bank.report writes out (the keys of fleet.experiments.bank.runner's), of recorded runs."""
    scenes: dict[str, dict] = {}
    for run in runs:
        scene = scenes.setdefault(run["scene"], {"group": run["group"], "about": _about(run["scene"]), "seeds": []})
        if run["seed"] not in scene["seeds"]:
            scene["seeds"].append(run["seed"])
    methods = dict.fromkeys(r["method"] for r in runs)
    return {
        "experiment": "bank",
        "command": command,
        "journals": journals,
        "machine": machine(),
        "environment": run_environment.environment(),
        "wall_time_s": None,
        "cpu_time_s": round(sum(r.get("cpu_s", 0.0) for r in runs), 1),
        "code": dict(Counter(r.get("code", "not recorded") for r in runs)),
        "env": dict(Counter(r.get("env", "not recorded") for r in runs)),
        "methods": {m: {"label": METHODS[m].label, "description": METHODS[m].description} for m in methods},
        "scenes": scenes,
        "fresh_generator_seeds": sorted({int(s.rsplit("-s", 1)[1]) for s, v in scenes.items()
                                         if v["group"] == "fresh" and s.rsplit("-s", 1)[-1].isdigit()}),
        "settings": {},
        "summary": bank_report.summarise(runs),
        "runs": runs,
    }


def _about(scene: str) -> str:
    if scene not in BANK:
        return ""
    try:
        return scene_data(scene)[1]
    except ConfigError:
        return ""


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg experiment bank-journals", __doc__)
    parser.add_argument("journals", nargs="+", metavar="FILE[:METHOD,...]",
                        help="a bank journal (runs.jsonl) and the methods to take from it (default: all)")
    parser.add_argument("--scenes", nargs="+", default=list(BANK), metavar="SCENE",
                        help="the bank scenes to report, in this order (default: the bank)")
    parser.add_argument("--seed", type=int, default=0, help="first seed of the bank scenes (default 0)")
    parser.add_argument("--seeds", type=int, default=100, help="seeds per bank scene (default 100)")
    parser.add_argument("--out", type=Path, default=Path("runs") / "bank-journals",
                        help="where bank.json, bank.md and bank.png go")
    parser.add_argument("--no-figures", action="store_true", help="skip the PNG figure")
    args = parser.parse_args(argv)
    if args.seeds < 1:
        parser.error("--seeds must be at least 1")
    takes = [configured("trustfg experiment bank-journals", lambda: parse_take(spec)) for spec in args.journals]
    journals = [(str(path), configured("trustfg experiment bank-journals", lambda: read_journal(path)), methods)
                for path, methods in takes]
    runs, repeats = configured("trustfg experiment bank-journals",
                               lambda: gather(journals, args.scenes, range(args.seed, args.seed + args.seeds)))
    if not runs:
        print("trustfg experiment bank-journals: no run of the selection in " + ", ".join(args.journals),
              file=sys.stderr)
        return 2
    missing = [f"{scene} {method}" for scene in args.scenes for method in dict.fromkeys(r["method"] for r in runs)
               if sum(r["scene"] == scene and r["method"] == method for r in runs) < args.seeds]
    print(f"{len(runs)} runs from {len(journals)} journals ({repeats} found twice, counted once)"
          + (f"; short of {args.seeds} seeds: {', '.join(missing)}" if missing else ""), file=sys.stderr)
    command = "trustfg experiment bank-journals " + " ".join(argv if argv is not None else sys.argv[1:])
    result = report(runs, command, {name: methods for name, _, methods in journals})
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "bank.json").write_text(json.dumps(result, indent=1))
    table = bank_report.markdown(result)
    (args.out / "bank.md").write_text(table)
    if not args.no_figures:
        bank_report.figure(result, args.out / "bank.png")
    print(table)
    print(f"wrote {args.out.resolve()}")
    return 0
