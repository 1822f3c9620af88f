"""examples/plan_one_car.py: car 1 planned alone would come too close to car 2; planned
around car 2's plan it keeps its distance, and both plans keep off the walls."""

import re

import pytest

from tests.examples.conftest import png

pytestmark = pytest.mark.realtime

LINE = re.compile(r"(alone|with peer): (\d+) iterations, error ([\d.]+) -> ([\d.]+), [\d.]+ ms; closest to car 2 "
                  r"([\d.]+) m \(clearance ([-+][\d.]+) m\), to the walls ([-+][\d.]+) m; verified: (True|False)")


def test_the_peer_constraint_keeps_car_1_clear_of_car_2(run_example, tmp_path):
    out = run_example("plan_one_car")
    plans = {m[1]: m for m in LINE.finditer(out)}
    assert set(plans) == {"alone", "with peer"}, out
    alone, around = plans["alone"], plans["with peer"]
    # alone, the two cars meet in the middle: closer than the breach distance, 0.3 m
    assert float(alone[5]) < 0.3 and float(alone[6]) < 0 and alone[8] == "False"
    # around the peer: beyond the breach distance by most of eps_0's margin (0.15 m)
    assert float(around[5]) > 0.4 and float(around[6]) > 0.1 and around[8] == "True"
    assert int(around[2]) >= 1 and float(around[4]) < float(around[3])  # the optimiser lowered the cost
    assert float(alone[7]) > 0 and float(around[7]) > 0  # both clear of the walls
    assert "plan_safely: first" in out or "plan_safely: retry" in out
    assert png(tmp_path / "plan_one_car.png")
