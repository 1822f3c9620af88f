"""Rechecking a journal: which runs to rerun, how a rerun differs, what names an environment."""

import json

from trustfg.fleet.experiments import run_environment
from trustfg.fleet.experiments.bank import recheck as bank_recheck

ENTRY = {"scene": "corridor-4", "method": "full", "seed": 3, "outcome": "success", "arrived": 4, "makespan_s": 26.18,
         "flowtime_s": 68.18, "least_clearance_m": 0.2199, "obstacle_min_clearance_m": 0.234, "breaches": [],
         "counters": {"plans_first": 600, "deadlocks": 1}, "wall_s": 9.1, "cpu_s": 9.0, "replan_ms_p95": 12.0,
         "code": "v0.3.0", "env": "envhere", "group": "bank", "fingerprint": "f" * 16}


def test_a_rerun_is_the_same_run_only_when_every_field_of_the_run_repeats():
    rerun = {k: v for k, v in ENTRY.items() if k not in ("code", "env", "group", "fingerprint")}
    rerun |= {"wall_s": 30.0, "cpu_s": 29.0, "replan_ms_p95": 40.0}  # the machine's, not the run's
    assert bank_recheck.differences(ENTRY, rerun) == []
    assert "the same (success" in bank_recheck.line(ENTRY, rerun, "envhere")
    for field, value in (("makespan_s", 25.96), ("least_clearance_m", 0.22), ("outcome", "timeout"),
                         ("counters", {"plans_first": 601, "deadlocks": 1})):
        changed = rerun | {field: value}
        assert bank_recheck.differences(ENTRY, changed) == [field]
        text = bank_recheck.line(ENTRY, changed, "envthere")
        assert "DIFFERS" in text and "journal env envhere" in text and "code v0.3.0" in text
    assert "same environment" in bank_recheck.line(ENTRY, rerun | {"makespan_s": 1.0}, "envhere")


def test_the_runs_to_recheck_are_drawn_the_same_way_each_time():
    runs = [dict(ENTRY, seed=seed) for seed in range(50)]
    picked = bank_recheck.pick(runs, 7)
    assert len(picked) == 7 == len({r["seed"] for r in picked})
    assert picked == bank_recheck.pick(runs, 7) and picked != bank_recheck.pick(runs, 7, seed=1)
    assert bank_recheck.pick(runs, 80) == runs


def test_an_environment_names_the_packages_and_the_kernels_a_run_goes_through(monkeypatch):
    monkeypatch.delenv("NUMBA_CPU_NAME", raising=False)
    env = run_environment.environment()
    assert env["packages"]["numpy"] and env["packages"]["gtsam"] and env["python"]
    assert env["numba_cpu"] and isinstance(env["numpy_dispatch"], list)
    json.dumps(env)  # goes into bank.json as it is
    here = run_environment.digest(env)
    assert len(here) == 12 and here == run_environment.digest(run_environment.environment())
    monkeypatch.setenv("NUMBA_CPU_NAME", "generic")  # compiled for another CPU: another environment
    assert run_environment.environment()["variables"]["NUMBA_CPU_NAME"] == "generic"
    assert run_environment.digest(run_environment.environment()) != here
