"""The scenario bank: methods as config, how a run is judged, the statistics, the command."""

import json
import subprocess
import sys

import numpy as np
import pytest

from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.trust import TrustBook
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.bank.report import bootstrap_ci, seeds_per_scene
from trustfg.fleet.experiments.bank.runner import METHODS, judge, parse_settings, scene_data, variant
from trustfg.fleet.sim.run_record import RunRecord


def test_the_baselines_are_config_changes_of_the_same_scene():
    data, _ = scene_data("corridor-4")
    full = variant(data, METHODS["full"].overrides)
    fixed = variant(data, METHODS["fixed"].overrides)
    wide = variant(data, METHODS["wide"].overrides, parse_settings(["sim.timeout_s=20"]))
    assert full == load_scenario("corridor-4")
    assert fixed.planner.proximity and not fixed.planner.consistency and not fixed.planner.transparency
    assert not fixed.trust.reject_plans and not wide.trust.reject_plans  # no trust: every plan believed
    assert wide.sim.timeout_s == 20.0
    eps_0 = full.safety.epsilon_0(0.1, 0.1)
    for scenario, gain in ((fixed, 1.0), (wide, 2.0)):
        book = TrustBook(owner=1, config=scenario.trust)
        book.record(2, 2, 0.0, 5.0, 0.0)  # a peer caught lying: trust would widen epsilon
        assert book.epsilon(2, 0.0, eps_0, scenario.planner.transparency) == pytest.approx(gain * eps_0)


@pytest.mark.parametrize("setting", ["planner", "planner.proximity", "planner.proximity=maybe", "=1"])
def test_bad_settings_are_refused(setting):
    with pytest.raises(ConfigError):
        parse_settings([setting])


def _record(paths, arrived, t_end=20.0):
    times = np.arange(0.0, t_end, 0.1)
    states = np.zeros((len(times), len(paths), 5))
    for i, path in enumerate(paths):
        states[:, i, :2] = np.array([path(t) for t in times])
    return RunRecord(seed=0, car_ids=[1, 2], radii=[0.1, 0.1], times=times, states=states, arrived_at=arrived,
                     depart_at=[0.0, 0.0], trust_times=np.zeros(0), trust=np.zeros(0), transparency=np.zeros(0),
                     epsilon=np.zeros(0), replan_ms=[[1.0], [2.0]], counters=[{"a": 1}, {"a": 2}], inbox=[{}, {}])


@pytest.fixture(scope="module")
def room():
    scenario = load_scenario("circle-4")
    scenario = scenario.__class__(**{**scenario.__dict__, "cars": scenario.cars[:2]})
    return scenario, build_sdf(scenario.world)


def test_a_run_is_judged_success_deadlock_timeout_or_breach(room):
    scenario, sdf = room
    goal_a, goal_b = np.array(scenario.cars[0].goal), np.array(scenario.cars[1].goal)
    start_b = np.array(scenario.cars[1].start)
    done = judge("s", "full", scenario, _record([lambda t: goal_a, lambda t: goal_b], [3.0, 4.0]), sdf)
    assert done["outcome"] == "success" and done["makespan_s"] == 4.0 and done["flowtime_s"] == 7.0
    assert done["counters"] == {"a": 3} and done["replan_ms_median"] == 1.5
    stuck = judge("s", "full", scenario, _record([lambda t: goal_a, lambda t: start_b], [3.0, None]), sdf)
    assert stuck["outcome"] == "deadlock" and stuck["makespan_s"] is None
    creeping = judge("s", "full", scenario,
                     _record([lambda t: goal_a, lambda t: start_b + [0.0, 0.02 * t]], [3.0, None]), sdf)
    assert creeping["outcome"] == "timeout"  # still moving at the end: not a deadlock
    crash = judge("s", "full", scenario, _record([lambda t: goal_a, lambda t: goal_a + [0.25, 0.0]], [3.0, None]), sdf)
    assert crash["outcome"] == "breach" and crash["least_clearance_m"] == pytest.approx(0.05)


def test_bootstrap_intervals_hold_the_estimate_narrow_with_more_runs_and_repeat():
    rng = np.random.default_rng(3)
    few, many = rng.uniform(size=20) < 0.9, rng.uniform(size=400) < 0.9
    lo, hi = bootstrap_ci(few, np.mean)
    assert 0.0 <= lo <= few.mean() <= hi <= 1.0
    lo_many, hi_many = bootstrap_ci(many, np.mean)
    assert hi_many - lo_many < hi - lo
    assert bootstrap_ci(few, np.mean) == (lo, hi)
    assert bootstrap_ci(np.zeros(50), np.mean) == (0.0, 0.0)
    assert bootstrap_ci([], np.median) is None


def _bank(*args):
    return subprocess.run([sys.executable, "-m", "trustfg", "experiment", "bank", *args], capture_output=True,
                          text=True, timeout=600)


@pytest.mark.slow
def test_the_bank_command_writes_results_and_carries_on_after_a_stop(tmp_path):
    args = ["--scenes", "corridor-4", "bottleneck-4", "--seeds", "1", "--seed", "300", "--methods", "fixed", "orca",
            "--jobs", "2", "--out", str(tmp_path)]
    done = _bank(*args)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "bank.json").read_text())
    assert len(report["runs"]) == 4 and (tmp_path / "bank.png").stat().st_size > 0
    code = report["runs"][0]["code"]  # the commit (or version) each run was made on
    assert code not in ("", "unknown") and report["code"] == {code: 4}
    assert f"run on {code} (4)" in (tmp_path / "bank.md").read_text()
    assert "| corridor-4 | ORCA | 1 |" in (tmp_path / "bank.md").read_text()
    for run in report["runs"]:
        assert run["scene"] in ("corridor-4", "bottleneck-4") and run["seed"] == 300
        assert (run["outcome"] == "breach") == bool(run["breaches"]) == (run["least_clearance_m"] < 0.1)
        assert (run["arrived"] == 4) == (run["makespan_s"] is not None) == (run["flowtime_s"] is not None)
        assert run["outcome"] != "success" or run["arrived"] == 4
    pooled = next(c for c in report["summary"] if c["scene"].startswith("all") and c["method"] == "orca")
    assert pooled["runs"] == 2 and sum(rate[0] for rate in pooled["rates"].values()) == pytest.approx(1.0)
    assert pooled["plans"]["retry_share"] is None  # ORCA makes no plans
    fixed = next(c for c in report["summary"] if c["scene"].startswith("all") and c["method"] == "fixed")
    assert fixed["plans"]["first"] > 0 and fixed["plans"]["unverified"] == 0  # the planner runs verified

    journal = (tmp_path / "runs.jsonl").read_text()
    again = _bank(*args)
    assert again.returncode == 0 and "4 runs already" in again.stderr
    assert (tmp_path / "runs.jsonl").read_text() == journal  # nothing ran twice

    wider = [*args[:3], "--seeds", "2", *args[5:]]
    report_only = _bank(*wider, "--report-only", "--no-figures")
    assert report_only.returncode == 0, report_only.stderr
    assert "4 runs of the selection" in report_only.stderr and "fixed 2, orca 2" in report_only.stderr
    assert (tmp_path / "runs.jsonl").read_text() == journal  # nothing ran
    assert len(json.loads((tmp_path / "bank.json").read_text())["runs"]) == 4
    assert "the journal's runs, none run now" in (tmp_path / "bank.md").read_text()
    nothing = _bank(*wider[:-1], str(tmp_path / "empty"), "--report-only")
    assert nothing.returncode == 2 and "no run of this selection" in nothing.stderr
    assert not (tmp_path / "empty").exists()  # nothing made where nothing was

    # Each run names its environment; a recheck reruns journal entries and finds the one
    # made to differ (the rest are the same to the last digit: one machine, one environment).
    env = report["runs"][0]["env"]
    assert len(env) == 12 and report["env"] == {env: 4} and report["environment"]["packages"]["gtsam"]
    entries = [{k: v for k, v in json.loads(line).items() if k != "env"} for line in journal.splitlines()]
    altered = next(e for e in entries if e["method"] == "fixed")
    altered["least_clearance_m"] += 0.001
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(e) + "\n" for e in entries))
    orca = [*wider[:8], *wider[9:]]  # one more seed of ORCA's, beside entries that name no environment
    carried = _bank(*orca, "--no-figures")
    assert carried.returncode == 0 and "ran in other environments (not recorded: 2)" in carried.stderr
    entries = entries + [json.loads(line) for line in (tmp_path / "runs.jsonl").read_text().splitlines()[4:]]
    assert [e["env"] for e in entries[4:]] == [env] * 2
    (tmp_path / "runs.jsonl").write_text("".join(json.dumps(e) + "\n" for e in entries))
    rechecked = _bank(*args, "--recheck", "9")
    assert rechecked.returncode == 1, rechecked.stderr
    assert "3 of 4 reruns the same" in rechecked.stdout
    lines = [line for line in rechecked.stderr.splitlines() if "DIFFERS" in line]
    assert len(lines) == 1 and f"{altered['scene']} fixed seed 300" in lines[0] and "least_clearance_m" in lines[0]
    result = json.loads((tmp_path / "recheck.json").read_text())
    assert result["same"] == 3 and result["env"] == env
    assert [r["differences"] for r in result["rechecked"] if not r["same"]] == [["least_clearance_m"]]


def test_bad_arguments_end_in_one_line(tmp_path):
    for args in (["--set", "planner.support_states=many"], ["--scenes", "no-such-scene"]):
        done = _bank(*args, "--seeds", "1", "--out", str(tmp_path))
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and "Traceback" not in done.stderr, done.stderr


def test_the_figure_title_says_how_many_seeds_each_group_of_scenes_ran():
    def report(**groups):
        return {"scenes": {f"{group}-{k}": {"group": group, "seeds": list(range(n))}
                           for group, ns in groups.items() for k, n in enumerate(ns)}}
    assert seeds_per_scene(report(bank=[100, 100], fresh=[5])) == "100 seeds per bank scene, 5 per held-out scene"
    assert seeds_per_scene(report(bank=[1])) == "1 seed per bank scene"
    assert seeds_per_scene(report(bank=[3, 2])) == "2/3 seeds per bank scene"
