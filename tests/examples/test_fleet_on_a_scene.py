"""examples/fleet_on_a_scene.py: the intersection's four cars all arrive, with no breach,
having driven about the length of their lanes."""

import re

import pytest

from tests.examples.conftest import png

pytestmark = pytest.mark.realtime


def test_every_car_arrives_without_a_breach(run_example, tmp_path):
    out = run_example("fleet_on_a_scene", "--scenario", "intersection", "--seed", "1")
    assert "intersection, seed 1: 4 cars" in out
    assert "reached goal: [True, True, True, True]" in out
    makespan = float(re.search(r"makespan ([\d.]+) s", out)[1])
    assert 5.0 < makespan < 40.0  # 4.3 m at 0.35-0.45 m/s, a start delay and some yielding
    driven = [float(m) for m in re.findall(r"drove ([\d.]+) m", out)]
    assert len(driven) == 4 and all(4.2 < d < 6.0 for d in driven)  # start to goal is 4.3 m
    assert "breaches: none" in out
    between, walls = map(float, re.search(r"between cars ([-\d.]+) m, to the walls ([-\d.]+) m", out).groups())
    assert between >= 0.1 and walls > 0.0  # the required clearance between cars; off the walls
    assert png(tmp_path / "fleet_on_a_scene.png")
