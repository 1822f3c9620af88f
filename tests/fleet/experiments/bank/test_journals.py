"""Reporting journals of several commits side by side (fleet.experiments.bank.journals)."""

import json
import subprocess
import sys

import pytest

from trustfg.agent.config import ConfigError
from trustfg.fleet.experiments.bank.journals import gather, parse_take, read_journal

pytestmark = pytest.mark.realtime


def _run(scene, method, seed, outcome="success", clearance=0.2, group="bank", code="v0.3.0"):
    return {"scene": scene, "method": method, "seed": seed, "cars": 4, "outcome": outcome,
            "least_clearance_m": clearance, "obstacle_min_clearance_m": 0.3, "breaches": [],
            "arrived": 4 if outcome == "success" else 3, "makespan_s": 12.0 if outcome == "success" else None,
            "flowtime_s": 40.0 if outcome == "success" else None, "replan_ms_median": 3.0, "replan_ms_p95": 5.0,
            "counters": {"plans_first_try": 10}, "wall_s": 1.0, "cpu_s": 1.0, "group": group, "code": code}


def _write(path, runs):
    path.write_text("".join(json.dumps(r) + "\n" for r in runs))
    return path


def test_a_take_names_a_journal_and_its_methods():
    assert parse_take("runs/a.jsonl:fixed,orca") == (parse_take("runs/a.jsonl")[0], ["fixed", "orca"])
    assert parse_take("a.jsonl")[1] == ["full", "fixed", "wide", "orca"]
    for bad in ("a.jsonl:rrt", "a.jsonl:", "a.jsonl:full,fast"):
        with pytest.raises(ConfigError, match="comma list"):
            parse_take(bad)


def test_a_journal_line_that_is_not_a_run_is_named(tmp_path):
    path = tmp_path / "runs.jsonl"
    path.write_text(json.dumps(_run("circle-4", "full", 0)) + "\n{not json\n")
    with pytest.raises(ConfigError, match=r"runs.jsonl:2: not a bank run"):
        read_journal(path)
    path.write_text(json.dumps({"scene": "circle-4", "seed": 0}) + "\n")
    with pytest.raises(ConfigError, match=r"runs.jsonl:1: not a bank run \(KeyError: 'method, outcome'\)"):
        read_journal(path)
    for not_an_object in ('"scene method seed outcome"', "[1, 2]", "7"):
        path.write_text(not_an_object + "\n")
        with pytest.raises(ConfigError, match=r"runs.jsonl:1: not a bank run \(TypeError"):
            read_journal(path)
    with pytest.raises(ConfigError, match="cannot read"):
        read_journal(tmp_path / "missing.jsonl")


def test_each_journal_gives_the_methods_named_for_the_scenes_and_seeds_chosen():
    shipped = [_run("circle-4", "full", s, code="new") for s in range(3)] + [_run("corridor-4", "full", 0, code="new")]
    older = ([_run("circle-4", m, s, code="old") for m in ("full", "fixed") for s in range(3)]
             + [_run("random-field-6-s7", "orca", 0, group="fresh", code="old")])
    runs, repeats = gather([("new", shipped, ["full"]), ("old", older, ["fixed", "orca"])], ["circle-4"], range(0, 2))
    assert repeats == 0
    assert [(r["scene"], r["method"], r["seed"], r["code"]) for r in runs] == [
        ("circle-4", "full", 0, "new"), ("circle-4", "full", 1, "new"),
        ("circle-4", "fixed", 0, "old"), ("circle-4", "fixed", 1, "old"),
        ("random-field-6-s7", "orca", 0, "old")]  # fresh scenes whatever --scenes says, after the bank


def test_a_run_in_two_journals_counts_once_and_two_different_runs_are_refused():
    entry = _run("circle-8", "orca", 0, code="old")
    same = entry | {"code": "new", "wall_s": 9.0, "cpu_s": 9.0}  # the machine's numbers are not the run's
    runs, repeats = gather([("a", [entry], ["orca"]), ("b", [same], ["orca"])], ["circle-8"], range(1))
    assert repeats == 1 and len(runs) == 1 and runs[0]["code"] == "old"
    other = entry | {"least_clearance_m": 0.25}
    with pytest.raises(ConfigError, match=r"circle-8 orca seed 0 is in a and b as different runs \(least_clearance_m\)"):
        gather([("a", [entry], ["orca"]), ("b", [other], ["orca"])], ["circle-8"], range(1))


def _journals(*args):
    return subprocess.run([sys.executable, "-m", "trustfg", "experiment", "bank-journals", *args],
                          capture_output=True, text=True, timeout=120)


def test_the_command_writes_one_table_of_several_journals(tmp_path):
    new = _write(tmp_path / "new.jsonl", [_run("corridor-4", "full", s, code="new") for s in range(2)])
    old = _write(tmp_path / "old.jsonl", [_run("corridor-4", "fixed", 0, code="old"),
                                          _run("corridor-4", "fixed", 1, outcome="timeout", code="old"),
                                          _run("corridor-4", "full", 0, outcome="timeout", code="old")])
    out = tmp_path / "report"
    done = _journals(f"{new}:full", f"{old}:fixed", "--scenes", "corridor-4", "--seeds", "3", "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert "4 runs from 2 journals" in done.stderr and "short of 3 seeds: corridor-4 full, corridor-4 fixed" in done.stderr
    table = (out / "bank.md").read_text()
    assert "| corridor-4 | 2/2, 0.200 m | 1/2 (1t), 0.200 m |" in table and "run on new (2), old (2)" in table
    assert (out / "bank.png").stat().st_size > 0
    report = json.loads((out / "bank.json").read_text())
    assert report["journals"] == {str(new): ["full"], str(old): ["fixed"]} and len(report["runs"]) == 4

    clash = _journals(str(new), str(old), "--scenes", "corridor-4", "--out", str(out))
    assert clash.returncode == 2 and clash.stderr.count("\n") == 1 and "as different runs" in clash.stderr
    empty = _journals(f"{new}:orca", "--out", str(tmp_path / "none"))
    assert empty.returncode == 2 and "no run of the selection" in empty.stderr
    assert not (tmp_path / "none").exists()
