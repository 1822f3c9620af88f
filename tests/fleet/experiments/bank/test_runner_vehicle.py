"""The bank with car-like cars (--vehicle car) and the tracking error it reports for every run."""

import argparse
import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.bank.report import cell
from trustfg.fleet.experiments.bank.runner import judge, parse_settings, scene_data, variant, with_vehicle
from trustfg.fleet.sim.in_process import simulate


def args(vehicle=None, radius=None) -> argparse.Namespace:
    return argparse.Namespace(vehicle=vehicle, min_turn_radius=radius)


def test_the_vehicle_options_are_settings_of_every_scene():
    settings = with_vehicle(parse_settings(["vehicle.wheelbase_m=0.2", "sim.timeout_s=20"]), args("car", 0.4))
    assert settings == {"vehicle": {"wheelbase_m": 0.2, "steering": "car", "min_turn_radius_m": 0.4},
                        "sim": {"timeout_s": 20}}
    data, _ = scene_data("corridor-4")
    car = variant(data, settings)
    assert car.vehicle.car_like and car.vehicle.min_turn_radius_m == 0.4
    assert with_vehicle({}, args()) == {}
    assert not variant(data, with_vehicle({}, args("in-place"))).vehicle.car_like
    with pytest.raises(ConfigError, match="--vehicle car"):
        with_vehicle({}, args(None, 0.3))


@pytest.fixture(scope="module")
def two_cars():
    scenario = load_scenario("circle-4")
    scenario = dataclasses.replace(scenario, cars=scenario.cars[:2],
                                   sim=dataclasses.replace(scenario.sim, timeout_s=25.0))
    return scenario, build_sdf(scenario.world)


@pytest.mark.parametrize("steering", ["in-place", "car"])
def test_every_run_says_how_closely_its_cars_followed_their_plans(two_cars, steering):
    """The in-process fleet records, per car and step it drove its plan unhindered, how far
    it was from where its plan had it; a run's journal entry holds the 95th percentile, a
    cell of the report its median and largest. Either kind of car follows within a few
    centimetres (the planner's margin, eps_0 - d_ab, is 15 cm)."""
    scenario, sdf = two_cars
    scenario = dataclasses.replace(scenario, vehicle=dataclasses.replace(scenario.vehicle, steering=steering))
    record = simulate(scenario, 0, sdf=sdf, record_trust=False)
    assert [len(errors) > 100 for errors in record.tracking_error] == [True, True]
    run = judge("circle-2", "full", scenario, record, sdf) | {"group": "bank"}
    assert run["outcome"] == "success"
    p95 = run["tracking_error_p95_m"]
    assert p95 == pytest.approx(np.percentile(np.concatenate(record.tracking_error), 95), abs=1e-4)
    assert 0.0 < p95 < 0.05
    summary = cell([run, run | {"tracking_error_p95_m": 2 * p95}])
    assert summary["tracking_error_p95_m"] == {"median": pytest.approx(1.5 * p95, abs=1e-4),
                                               "max": pytest.approx(2 * p95, abs=1e-4)}
