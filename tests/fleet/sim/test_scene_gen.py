"""Generated scenes: every kind, the shipped bank regenerates from its header, bad scenes are refused."""

import dataclasses
import re
import subprocess
import sys

import numpy as np
import pytest

from trustfg.agent.config import CarConfig, ConfigError, Scenario, WorldConfig
from trustfg.agent.routes import segment_clear
from trustfg.agent.scenario_files import dump_scenario, load_scenario, read_source
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.bank.runner import BANK
from trustfg.fleet.sim.scene_gen import KINDS, check_scene, cut_off_by_parked, generate, scene_file_text, scene_problem

SIZES = {"circle": 8, "circle-obstacles": 8, "corridor": 4, "bottleneck": 4, "t-junction": 6, "warehouse": 8,
         "random-field": 6}


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_kind_makes_checked_scenes_whose_routes_keep_clear_of_obstacles(kind):
    for seed in (11, 12):
        scenario, _ = generate(kind, SIZES[kind], seed)
        sdf = build_sdf(scenario.world)
        check_scene(scenario, sdf)
        assert len(scenario.cars) == SIZES[kind]
        for car in scenario.cars:
            eps_obs = scenario.safety.epsilon_obstacle(car.radius_m)
            points = np.array([car.start, *car.route, car.goal])
            assert all(segment_clear(sdf, a, b, eps_obs) for a, b in zip(points[:-1], points[1:]))
        again, _ = generate(kind, SIZES[kind], seed)
        assert again == scenario  # a seed makes one scene


@pytest.mark.parametrize("kind", ["circle-obstacles", "corridor", "t-junction", "warehouse", "random-field"])
def test_different_seeds_make_different_scenes(kind):
    assert generate(kind, SIZES[kind], 1)[0] != generate(kind, SIZES[kind], 2)[0]


@pytest.mark.parametrize("name", BANK)
def test_the_shipped_bank_regenerates_from_the_command_in_its_header(name):
    text, _ = read_source(name)
    match = re.search(r"--kind (\S+) --cars (\d+) --seed (\d+) --name (\S+)", text)
    kind, cars, seed, scene = match.group(1), int(match.group(2)), int(match.group(3)), match.group(4)
    scenario, about = generate(kind, cars, seed, scene)
    assert scene == name
    assert scene_file_text(scenario, kind, cars, seed, about) == text
    assert load_scenario(name) == scenario


def test_a_start_inside_an_obstacle_or_next_to_another_car_is_refused():
    scenario, _ = generate("warehouse", 4, 3)
    rack = scenario.world.obstacles[0]
    inside = ((rack.min[0] + rack.max[0]) / 2, 0.0)
    bad = dataclasses.replace(scenario, cars=(dataclasses.replace(scenario.cars[0], start=inside), *scenario.cars[1:]))
    with pytest.raises(ConfigError, match="car 1's start"):
        check_scene(bad)
    near = (scenario.cars[1].start[0] + 0.3, scenario.cars[1].start[1])
    bad = dataclasses.replace(scenario, cars=(scenario.cars[0], scenario.cars[1],
                                              dataclasses.replace(scenario.cars[2], start=near), *scenario.cars[3:]))
    with pytest.raises(ConfigError, match="starts of cars 2 and 3"):
        check_scene(bad)


def _trustfg(*args):
    return subprocess.run([sys.executable, "-m", "trustfg", *args], capture_output=True, text=True, timeout=120)


def test_the_command_writes_a_scene_and_refuses_bad_ones_in_one_line(tmp_path):
    out = tmp_path / "t.toml"
    done = _trustfg("scenario", "generate", "--kind", "t-junction", "--cars", "6", "--seed", "4", "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert len(load_scenario(out).cars) == 6
    assert _trustfg("scenario", "check", str(out)).returncode == 0

    text = out.read_text()
    first_start = re.search(r"start = \[[^\]]*\]", text).group(0)
    out.write_text(text.replace(first_start, "start = [-3.0, -3.0]", 1))  # in the corner block
    bad = _trustfg("scenario", "check", str(out))
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "Traceback" not in bad.stderr and "car 1's start" in bad.stderr

    too_many = _trustfg("scenario", "generate", "--kind", "t-junction", "--cars", "20", "--out", str(out))
    assert too_many.returncode == 2 and too_many.stderr.count("\n") == 1 and "at most 12" in too_many.stderr


def _corridor(parked_at: tuple[float, float]) -> Scenario:
    """A corridor 1.2 m wide; car 2 parks at ``parked_at``, car 1 drives its length."""
    return Scenario(name="corridor", world=WorldConfig(bounds_m=(-2.0, -0.6, 2.0, 0.6)),
                    cars=(CarConfig(id=1, start=(-1.5, 0.0), goal=(1.5, 0.0)),
                          CarConfig(id=2, start=(1.5, -0.3), goal=parked_at)))


def test_a_car_parked_in_the_way_is_refused_and_one_in_a_bay_is_not():
    """Parked mid-corridor, car 2 leaves no eps_0 gap: car 1 could never pass once car 2
    arrives first. Parked against the wall, it leaves 0.23 m of room to pass."""
    in_the_way, in_a_bay = _corridor((0.0, 0.0)), _corridor((0.0, -0.33))
    sdf = build_sdf(in_the_way.world)
    assert cut_off_by_parked(in_the_way, in_the_way.cars[0], sdf)
    assert not cut_off_by_parked(in_a_bay, in_a_bay.cars[0], sdf)
    with pytest.raises(ConfigError, match="car 1 cannot reach its goal"):
        check_scene(in_the_way)
    check_scene(in_a_bay)
    assert "car 1 cannot reach its goal" in scene_problem(in_the_way)  # what sim and check warn
    assert scene_problem(in_a_bay) is None


def test_the_command_refuses_a_scene_with_a_car_parked_in_the_way(tmp_path):
    out = tmp_path / "corridor.toml"
    out.write_text(dump_scenario(_corridor((0.0, 0.0))))
    bad = _trustfg("scenario", "check", str(out))
    assert bad.returncode == 2
    assert bad.stderr.count("\n") == 1 and "car 1 cannot reach its goal" in bad.stderr


def test_a_goal_on_another_cars_start_does_not_cut_that_car_off():
    """A swap: each car's goal is the other's start, reached only after the other left."""
    swap = Scenario(name="swap", world=WorldConfig(bounds_m=(-2.0, -0.6, 2.0, 0.6)),
                    cars=(CarConfig(id=1, start=(-1.5, 0.0), goal=(1.5, 0.0)),
                          CarConfig(id=2, start=(1.5, 0.0), goal=(-1.5, 0.0))))
    check_scene(swap)
