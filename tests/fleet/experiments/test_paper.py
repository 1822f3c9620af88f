"""The paper's claims, checked over many seeds in the in-process fleet simulation.

Seeds 100.. are used here so the tests do not share seeds with the documented runs
(seeds 0..19); nothing is tuned to them.
"""

import dataclasses
import os

import numpy as np
import pytest

from trustfg.fleet.experiments.paper import detection_delay, run_experiment, summarise
from trustfg.fleet.sim.in_process import simulate

SEEDS = list(range(100, 108))
JOBS = min(2, os.cpu_count() or 1)


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    return tmp_path_factory.mktemp("experiments")


@pytest.fixture(scope="module")
def made():
    """The runs of this module's experiments, shared as in `trustfg experiment all`."""
    return {}


def test_a_run_is_deterministic_per_seed(intersection):
    first = simulate(intersection, 5)
    second = simulate(intersection, 5)
    assert np.array_equal(first.states, second.states)
    assert np.array_equal(first.trust, second.trust)
    other = simulate(intersection, 6)
    assert not np.array_equal(first.states[:50], other.states[:50])  # desynchronised starts


@pytest.mark.slow
def test_proximity_factors_prevent_breaches_that_happen_without_them(out, made):
    report = run_experiment("proximity", SEEDS, out, JOBS, figures=False, variants=("on", "off"), made=made)
    on, off = report["variants"]["on"], report["variants"]["off"]
    assert all(not run["breaches"] for run in on)
    assert all(all(run["reached_goal"]) for run in on)
    assert sum(1 for run in off if run["breaches"]) >= len(SEEDS) / 2
    assert all(run["obstacle_min_clearance"] >= 0.1 for run in on)


@pytest.mark.slow
def test_transparency_widens_the_berth_around_a_liar(out, made):
    report = run_experiment("transparency", SEEDS, out, JOBS, figures=False, made=made)
    summary = report["summary"]
    # Clearly wider, not the paper's 2x: verification and the guard hold the liar off without
    # trust too, so the bar is 1.3, below what the documented seeds show
    # (docs/results/paper-experiments.md).
    assert summary["liar_distance_ratio"] >= 1.3
    on = report["variants"]["on"]
    assert all(not run["breaches"] for run in on)
    for run in on:
        assert run["trust_separated_at_s"] is not None and run["trust_separated_at_s"] <= 3.0
        assert run["honest_trust_min_after_settle"] > 0.8
        assert run["trust_gap_min_after_settle"] >= 0.2


@pytest.mark.slow
def test_consistency_factor_lowers_the_inconsistency_index(out, made):
    report = run_experiment("consistency", SEEDS, out, JOBS, figures=False, made=made)
    summary = report["summary"]
    assert summary["on"]["inconsistency_mean"] < summary["off"]["inconsistency_mean"]
    assert summary["inconsistency_lower_with_factor_in_seeds"] >= len(SEEDS) / 2


def test_run_summary_has_every_documented_key(intersection):
    record = simulate(dataclasses.replace(intersection, cars=intersection.cars[:2]), 1)
    run = summarise(intersection, record)
    for key in ("seed", "car_ids", "min_distance", "min_clearance", "breaches", "obstacle_min_clearance",
                "reached_goal", "makespan_s", "inconsistency", "trust"):
        assert key in run
    assert np.allclose(np.diag(run["min_distance"]), 0.0)
    assert len(run["trust"]) == 2


@pytest.mark.slow
def test_liars_are_found_out_and_slander_sinks_no_one():
    """A few attacks, trust on, in the lab's left turns (seeds of their own): every liar
    that tells a lie the audit can check is detected within 3 s of it, and a slanderer
    costs no honest car its trust."""
    from trustfg.fleet.experiments.adversaries import run_matrix
    results = run_matrix(["lab"], ["displaced", "false-future", "collude", "slander"], ["on"],
                         [300, 301], JOBS, label="test")["lab"]
    for attack, by_variant in results.items():
        for run in by_variant["on"]:
            if run["first_lie_s"] is not None:
                assert run["detection_delay_s"] is not None and run["detection_delay_s"] <= 3.0, (attack, run["seed"])
    assert all(run["first_lie_s"] is not None for attack in ("displaced", "false-future", "collude")
               for run in results[attack]["on"])
    assert all(run["honest_trust_min_after_settle"] >= 0.8 for run in results["slander"]["on"])


def test_each_liar_of_a_pair_is_timed_from_its_own_lies():
    """A colluding pair: car 3 lies first at -1.62 s, car 1 at -0.7 s and is caught at
    1.4 s -- 2.1 s after its own lie, not 3.02 s after its partner's; a liar that never
    lied is not waited for, one never caught leaves None."""
    assert detection_delay([1.4, 0.5], [-0.7, -1.62]) == pytest.approx(2.12)
    assert detection_delay([None, 0.5], [None, -1.62]) == pytest.approx(2.12)
    assert detection_delay([None, 0.5], [-0.7, -1.62]) is None
    assert detection_delay([None, None], [None, None]) is None


@pytest.mark.slow
def test_a_car_with_a_skewed_clock_stays_trusted_under_loss_and_delay(lab):
    """30 % of messages lost, 50 +- 20 ms delay, and car 2's clock 0.3 s ahead: every peer
    keeps trusting car 2 (>= 0.8 after 3 s). (test_defences shows the clock estimate at
    work: at these speeds a 0.3 s skew misplaces a plan by 0.10-0.14 m, just under the
    tolerance; at 0.6 m/s it would read as lying.)"""
    lossy = dataclasses.replace(
        lab, sim=dataclasses.replace(lab.sim, message_loss=0.3, message_latency_s=0.03, message_jitter_s=0.04),
        cars=tuple(dataclasses.replace(c, clock_offset_s=0.3) if c.id == 2 else c for c in lab.cars))

    def trust_in_car_2(seed):
        record = simulate(lossy, seed)
        after = record.trust_times >= 3.0
        skewed = record.car_ids.index(2)
        return min(record.trust[after][:, a, skewed].min() for a in range(4) if a != skewed)

    for seed in (310, 311):
        assert trust_in_car_2(seed) >= 0.8, seed


def test_the_fair_off_keeps_eps_0_from_every_peer_where_trust_starts_wider(intersection):
    from trustfg.fleet.experiments.paper import EXPERIMENTS

    short = dataclasses.replace(intersection, sim=dataclasses.replace(intersection.sim, timeout_s=3.0))
    eps_0 = intersection.safety.epsilon_0(0.1, 0.1)
    off_diagonal = ~np.eye(len(intersection.cars), dtype=bool)
    fixed = simulate(EXPERIMENTS["proximity"].variants["fixed"](short), 3).epsilon[:, off_diagonal]
    on = simulate(EXPERIMENTS["proximity"].variants["on"](short), 3).epsilon[:, off_diagonal]
    assert np.allclose(fixed, eps_0)
    assert on[0].min() > 1.2 * eps_0  # trust starts at the prior (2/3): a wider berth until it grows


def test_cars_that_stand_before_the_go_are_strangers_no_more_at_the_go(lab):
    """The fleet waits sim.settle_s at the starts, as trustfg sim's cars do: their standing
    plans, heard and seen to come true, lift every peer off the prior before anyone moves.
    Without the wait every peer is a stranger at the go (the prior, 2/3)."""
    def at_the_go(settle_s, seed):
        scene = dataclasses.replace(lab, sim=dataclasses.replace(lab.sim, settle_s=settle_s, timeout_s=0.1))
        record = simulate(scene, seed)
        assert record.trust_times[0] <= -settle_s + 0.1  # the trust record starts with the wait
        trust = record.trust[int(np.argmin(np.abs(record.trust_times)))]
        return trust[~np.eye(len(record.car_ids), dtype=bool)]

    for seed in range(120, 124):
        cold, settled = at_the_go(0.0, seed), at_the_go(2.0, seed)
        assert cold.max() < 0.7, seed
        assert settled.min() >= 0.8, seed


TWO_CARS = """
name = "two-cars"
[world]
bounds_m = [-1.5, -1.5, 1.5, 1.5]
obstacles = []
[sim]
timeout_s = 20.0
[[cars]]
id = 1
start = [-1.0, 0.2]
goal = [1.0, 0.2]
[[cars]]
id = 2
start = [1.0, -0.2]
goal = [-1.0, -0.2]
"""


def test_experiments_of_one_call_run_a_fleet_they_share_once(tmp_path, capsys):
    """Proximity's "on" and consistency's "on" are one fleet: the second experiment takes
    the first's run of it and runs only its own "off"."""
    scene = tmp_path / "two-cars.toml"
    scene.write_text(TWO_CARS)
    made = {}
    proximity = run_experiment("proximity", [7], tmp_path, 1, str(scene), figures=False, variants=("on",), made=made)
    assert len(made) == 1
    consistency = run_experiment("consistency", [7], tmp_path, 1, str(scene), figures=False, made=made)
    assert len(made) == 2  # its "off" (no consistency factor) is a fleet of its own
    assert consistency["variants"]["on"] == proximity["variants"]["on"]
    assert consistency["variants"]["off"] != consistency["variants"]["on"]
    assert "1 of 2 runs not run again: the same fleet and seed as a run before them" in capsys.readouterr().err
