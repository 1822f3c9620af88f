"""The ORCA baseline: the command map, its radius, and that ORCA is what keeps its cars apart."""

import math
import sys

import numpy as np
import pytest

from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.sim import orca
from trustfg.fleet.sim.in_process import draw_departures
from trustfg.fleet.sim.run_record import motion_summary

SEEDS = range(200, 208)


@pytest.fixture(scope="module")
def circle4():
    scenario = load_scenario("circle-4")
    return scenario, build_sdf(scenario.world)


def test_the_command_moves_the_lead_point_with_orcas_velocity():
    rng = np.random.default_rng(1)
    lead = 0.1
    for _ in range(200):
        yaw = rng.uniform(-math.pi, math.pi)
        heading, side = np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])
        u = rng.normal(0, 0.4, 2)
        v, omega = orca.unicycle_command(u[0], u[1], yaw, lead)
        moved = v * heading + lead * omega * side  # velocity of p + lead * heading
        if u @ heading >= 0:
            assert np.allclose(moved, u)
        else:
            assert v == 0.0 and np.isclose(moved @ side, u @ side)  # never backwards


def test_two_orca_agents_apart_keep_two_car_bodies_the_required_clearance(circle4):
    scenario, _ = circle4
    r = scenario.cars[0].radius_m
    agent = orca.orca_radius(scenario, r)
    # lead points >= 2 * agent apart, each body within r + lead (lead = r) of its point
    assert 2 * agent - 2 * (r + r) >= scenario.safety.clearance_m - 1e-12
    assert 2 * agent >= scenario.safety.epsilon_0(r, r)


def test_orca_drives_the_same_departures_and_keeps_the_cars_apart(circle4):
    scenario, sdf = circle4
    for seed in SEEDS:
        record = orca.simulate_orca(scenario, seed, sdf)
        depart, _ = draw_departures(scenario, np.random.default_rng(seed))
        assert np.allclose(record.depart_at, depart)
        run = motion_summary(scenario, record, sdf)
        assert not run["breaches"] and run["obstacle_min_clearance"] >= 0.1
        assert all(run["reached_goal"])


def test_without_orcas_radius_the_same_cars_collide(circle4, monkeypatch):
    scenario, sdf = circle4
    monkeypatch.setattr(orca, "orca_radius", lambda scenario, radius: 0.01)
    breached = sum(bool(motion_summary(scenario, orca.simulate_orca(scenario, seed, sdf), sdf)["breaches"])
                   for seed in SEEDS)
    assert breached >= len(SEEDS) / 2


def test_without_pyrvo_the_baseline_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyrvo", None)
    with pytest.raises(orca.MissingLibrary, match=r"\[baselines\]"):
        orca.simulate_orca(load_scenario("circle-4"), 0)
