"""The whole fleet as OS processes: real Zenoh, real UDP, real NatNet bytes, real GTSAM."""

import json

import pytest

from trustfg.fleet.launch import loopback_fleet, run


@pytest.fixture(scope="module")
def honest(intersection, tmp_path_factory):
    out = tmp_path_factory.mktemp("honest")
    return out, run(loopback_fleet(intersection, None, None, 0.0), out, seed=11)


@pytest.fixture(scope="module")
def liar(lab, tmp_path_factory):
    out = tmp_path_factory.mktemp("liar")
    return out, run(loopback_fleet(lab, None, 1, 0.4), out, seed=12)


def test_four_car_processes_reach_their_goals_without_breach(honest):
    out, summary = honest
    assert summary["crashed"] == []
    assert all(summary["reached_goal"]), summary["reached_goal"]
    assert summary["breaches"] == []
    assert summary["obstacle_min_clearance"] >= 0.1
    for name in ("fleet.toml", "messages.jsonl", "ground_truth.csv", "summary.json", "car_1.json", "car_1.log"):
        assert (out / name).exists(), name
    # Every car heard every other one and was heard: plans, trust, poses, status all flowed.
    for car, counts in summary["messages_per_car"].items():
        assert {"plan", "trust", "pose", "status"} <= set(counts), (car, counts)
    assert json.loads((out / "summary.json").read_text())["car_ids"] == [1, 2, 3, 4]
    # Each car process replanned while commanding.
    for car in map(str, summary["car_ids"]):
        assert summary["replan_ms"][car]["count"] > 10
        assert summary["control"][car]["sent"] > 100
        # Its CPU, from /proc: a planning car is busy, but far from a whole core.
        cpu = summary["cpu"][f"car {car}"]
        assert 0.01 < cpu["share"] < 1.0 and cpu["share_go_first_arrival"] > 0.01, cpu
    assert summary["cpu"]["mocap-sim"]["cpu_s"] > 0 and summary["cpu"]["launcher"]["cpu_s"] > 0


def test_honest_cars_distrust_a_liar_over_the_network(liar):
    out, summary = liar
    assert summary["crashed"] == [] and summary["breaches"] == []
    assert all(summary["reached_goal"])
    ids = summary["car_ids"]
    trust = summary["trust"]
    liar_index = ids.index(1)
    honest = [k for k, i in enumerate(ids) if i != 1]
    for a in honest:
        peers = [trust[a][b] for b in honest if b != a]
        assert min(peers) > 0.8, trust[a]
        assert trust[a][liar_index] <= min(peers) - 0.2, trust[a]
