"""Which shipped scene ``trustfg sim`` runs for a fleet size, and what it says when none fits."""

import subprocess
import sys

import pytest

from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.launch.launcher import DEFAULT_SCENES, default_scenario, loopback_fleet

pytestmark = pytest.mark.realtime


@pytest.mark.parametrize("cars", [None, 1, 4, 5, 8, 9, 16])
def test_the_default_scene_is_the_smallest_shipped_one_with_enough_cars(cars):
    name = default_scenario(cars)
    assert len(load_scenario(name).cars) >= (cars or 1)
    sizes = dict(DEFAULT_SCENES)
    assert all(size < cars for size in sizes.values() if size < sizes[name])  # no smaller one would do


def test_every_default_scene_has_the_cars_it_is_listed_with():
    for name, size in DEFAULT_SCENES:
        assert len(load_scenario(name).cars) == size


def test_more_cars_than_any_default_scene_says_how_to_make_one():
    with pytest.raises(ConfigError, match=r"no shipped scene has 17 cars.*scenario generate --kind circle --cars 17"):
        default_scenario(17)


def test_too_few_cars_in_a_named_scene_names_it():
    with pytest.raises(ConfigError, match=r"scenario 'intersection-8' has 8 cars, 9 were asked for"):
        loopback_fleet(load_scenario("intersection-8"), 9)


def test_trustfg_sim_with_more_cars_than_any_scene_exits_with_the_reason():
    done = subprocess.run([sys.executable, "-m", "trustfg", "sim", "--cars", "40", "--no-dashboard"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert "no shipped scene has 40 cars" in done.stderr and "Traceback" not in done.stderr
