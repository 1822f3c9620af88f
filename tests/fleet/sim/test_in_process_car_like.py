"""Car-like cars in the in-process fleet: a car that starts facing away from its route
drives round on an arc it can make and arrives; no car-like car ever turns standing or
curves tighter than its radius."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent.config import CarConfig, Scenario, SimConfig, VehicleConfig, WorldConfig
from trustfg.fleet.sim.in_process import simulate

CAR = VehicleConfig(steering="car", min_turn_radius_m=0.3)


def open_field(*cars: CarConfig) -> Scenario:
    return Scenario(name="field", cars=cars, world=WorldConfig(bounds_m=(-2.5, -2.5, 2.5, 2.5)), vehicle=CAR,
                    sim=SimConfig(timeout_s=30.0, start_delay_max_s=0.0))


def curvature_and_standing_turns(record) -> tuple[float, int]:
    v, omega = record.states[..., 3], record.states[..., 4]
    moving = v > 0.02
    return float(np.max(np.abs(omega[moving]) / v[moving])), int(np.sum((np.abs(v) < 1e-3) & (np.abs(omega) > 1e-3)))


@pytest.mark.parametrize("heading", [math.pi, math.pi / 2, -2.5])
def test_a_car_facing_away_from_its_route_drives_round_and_arrives(heading):
    """Goal 2.5 m east, the car facing west, north or south-west: its first plan sets off
    along its heading and turns it round on arcs of at least R_min."""
    scenario = open_field(CarConfig(id=1, start=(-1.25, 0.0), goal=(1.25, 0.0), start_heading_rad=heading))
    record = simulate(scenario, 0, record_trust=False)
    assert record.arrived_at[0] is not None
    curvature, turned_standing = curvature_and_standing_turns(record)
    assert curvature <= 1 / CAR.min_turn_radius_m + 1e-6 and turned_standing == 0
    # It did turn round: its path left the straight line by at least a turning radius.
    assert np.max(np.abs(record.states[:, 0, 1])) > 0.25


def test_two_car_like_cars_crossing_keep_their_distance():
    scenario = open_field(CarConfig(id=1, start=(-1.5, 0.0), goal=(1.5, 0.0)),
                          CarConfig(id=2, start=(0.0, -1.5), goal=(0.0, 1.5)))
    scenario = dataclasses.replace(scenario, sim=dataclasses.replace(scenario.sim, start_delay_max_s=0.5))
    record = simulate(scenario, 1, record_trust=False)
    assert all(a is not None for a in record.arrived_at)
    gaps = np.linalg.norm(record.states[:, 0, :2] - record.states[:, 1, :2], axis=1)
    assert gaps.min() > scenario.safety.breach_distance(0.1, 0.1)
    curvature, turned_standing = curvature_and_standing_turns(record)
    assert curvature <= 1 / CAR.min_turn_radius_m + 1e-6 and turned_standing == 0


@pytest.mark.parametrize("goal", [(-0.8, -0.3), (-0.4, 0.2), (-0.3, 0.0)])
def test_a_car_facing_away_from_a_goal_close_behind_it_loops_round_and_arrives(goal):
    """The goal lies behind a car facing north-east, nearer than the loop it takes to face
    it (in two of the three inside its left turning circle): its plans get the time of
    that loop, not of the straight, and it arrives, never turning standing or tighter than
    its radius."""
    scenario = open_field(CarConfig(id=1, start=(0.0, 0.0), goal=goal, start_heading_rad=0.5))
    record = simulate(scenario, 0, record_trust=False)
    assert record.arrived_at[0] is not None
    curvature, turned_standing = curvature_and_standing_turns(record)
    assert curvature <= 1 / CAR.min_turn_radius_m + 1e-6 and turned_standing == 0
