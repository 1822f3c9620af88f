import dataclasses

import pytest

from tests.conftest import SCENARIOS
from trustfg.agent.config import ConfigError, PlannerConfig, SafetyConfig, with_overrides
from trustfg.agent.scenario_files import load_scenario, scenario_from_dict, shipped


def minimal(**extra):
    data = {"name": "t", "cars": [{"id": 1, "start": [0.0, 0.0], "goal": [1.0, 0.0]}]}
    data.update(extra)
    return data


def test_shipped_scenarios_load():
    for path in SCENARIOS.glob("*.toml"):
        scenario = load_scenario(path)
        assert scenario.cars, path
        assert len({c.id for c in scenario.cars}) == len(scenario.cars)


def test_paper_lab_coordinates(lab):
    starts = [c.start for c in lab.cars]
    goals = [c.goal for c in lab.cars]
    assert starts == [(0.4, -2.15), (-0.4, 2.15), (-2.15, -0.4), (2.15, 0.4)]
    assert goals == [(-2.15, 0.4), (2.15, -0.4), (0.4, 2.15), (-0.4, -2.15)]


def test_defaults_fill_what_a_file_leaves_out():
    scenario = scenario_from_dict(minimal())
    assert scenario.planner == PlannerConfig()
    assert scenario.cars[0].radius_m == 0.1


@pytest.mark.parametrize("data, message", [
    (minimal(planner={"support_states": "many"}), "planner.support_states: expected an integer"),
    (minimal(planner={"suport_states": 21}), "planner.suport_states: unknown key"),
    (minimal(planner={"qc": -1.0}), "planner.qc: must be > 0"),
    (minimal(planner={"interpolation": "cubic"}), "planner.interpolation"),
    (minimal(trust={"forgetting": 1.5}), "trust.forgetting"),
    (minimal(world={"obstacles": [{"kind": "rect", "min": [1, 1], "max": [0, 0]}]}), "world.obstacles[0]"),
    (minimal(world={"obstacles": [{"kind": "circle"}]}), "world.obstacles[0].kind"),
    (minimal(world={"bounds_m": [0, 0, 1]}), "world.bounds_m: expected 4 values"),
    (minimal(sim={"timeout_s": True}), "sim.timeout_s: expected a number"),
    ({"name": "t", "cars": [{"id": 1, "start": [0, 0]}]}, "cars[0].goal: missing required key"),
    ({"name": "t", "cars": [{"id": 0, "start": [0, 0], "goal": [1, 1]}]}, "cars[0].id"),
    ({"name": "t", "cars": [{"id": 1, "start": [0, 0], "goal": [1, 1]},
                            {"id": 1, "start": [0, 1], "goal": [1, 0]}]}, "car ids must be unique"),
    ({"name": "t", "cars": []}, "cars: a scenario needs at least one car"),
    ({"cars": [{"id": 1, "start": [0, 0], "goal": [1, 1]}]}, "name: missing required key"),
    (minimal(cars=[{"id": 1, "start": [0, 0], "goal": [1, 1], "attack": {"name": "displaced", "params": {"p": 2.0}}}]),
     "attack.params.p"),
    (minimal(cars=[{"id": 1, "start": [0, 0], "goal": [1, 1], "attack": {"name": "nonsense"}}]), "attack.name"),
    (minimal(cars=[{"id": 1, "start": [0, 0], "goal": [1, 1], "attack": {"name": "bias", "params": {"p": 0.5}}}]),
     "attack.params.p"),
    # a liar can bias its plans by anything under the tolerance unnoticed: the margin must cover it
    (minimal(safety={"peer_margin_m": 0.1}), "safety.peer_margin_m (0.1) must be at least trust.transparency_tolerance_m"),
    (minimal(sim={"message_loss": 1.0}), "sim.message_loss"),
    (minimal(cars=[{"id": 1, "start": [0, 0], "goal": [1, 1], "clock_offset_s": 100.0}]), "cars[0].clock_offset_s"),
])
def test_bad_config_names_the_key(data, message):
    with pytest.raises(ConfigError) as info:
        scenario_from_dict(data)
    assert message in str(info.value)


def test_bad_file_errors(tmp_path):
    missing = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="no such file, nor a shipped scenario"):
        load_scenario(missing)
    broken = tmp_path / "broken.toml"
    broken.write_text("name = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_scenario(broken)
    wrong = tmp_path / "wrong.toml"
    wrong.write_text('name = "x"\n[[cars]]\nid = 1\nstart = [0, 0]\ngoal = [1, 1]\n[planner]\nqc = "big"\n')
    with pytest.raises(ConfigError, match=r"wrong.toml: planner.qc: expected a number"):
        load_scenario(wrong)


def test_shipped_scenes_load_by_name_and_a_file_wins_over_a_name(tmp_path, monkeypatch):
    assert {"intersection", "intersection-8", "lab"} <= set(shipped())
    assert load_scenario("intersection") == load_scenario("scenarios/intersection.toml")
    assert load_scenario("lab/fleet").fleet == "lab"
    monkeypatch.chdir(tmp_path)
    (tmp_path / "intersection").write_text('name = "mine"\n[[cars]]\nid = 1\nstart = [0, 0]\ngoal = [1, 1]\n')
    assert load_scenario("intersection").name == "mine"
    with pytest.raises(ConfigError, match="shipped: .*intersection, .*intersection-8, .*lab"):
        load_scenario("no-such-scene")


def test_safety_distances_follow_the_radii():
    safety = SafetyConfig()
    assert safety.breach_distance(0.1, 0.1) == pytest.approx(0.3)
    assert safety.epsilon_0(0.1, 0.1) == pytest.approx(0.45)
    assert safety.epsilon_obstacle(0.1) == pytest.approx(0.25)
    assert safety.epsilon_0(0.3, 0.1) - safety.epsilon_0(0.1, 0.1) == pytest.approx(0.2)


def test_overrides_are_validated(intersection):
    changed = with_overrides(intersection.planner, support_states=41)
    assert changed.support_states == 41
    with pytest.raises(ConfigError):
        with_overrides(intersection.planner, support_states=1)


def test_config_is_immutable(intersection):
    with pytest.raises(dataclasses.FrozenInstanceError):
        intersection.planner.qc = 3.0  # type: ignore[misc]


@pytest.mark.parametrize("changed_only", [False, True])
def test_dump_and_load_round_trip(tmp_path, lab, changed_only):
    """Also with a liar: an attack (a table with a required name) is written whole."""
    from trustfg.agent.config import AttackConfig
    from trustfg.agent.scenario_files import dump_scenario
    liar = dataclasses.replace(lab, cars=tuple(
        dataclasses.replace(c, attack=AttackConfig("bias", {"bias_m": 0.1})) if c.id == 1 else c for c in lab.cars))
    for scenario in (lab, liar):
        path = tmp_path / "again.toml"
        path.write_text(dump_scenario(scenario, changed_only=changed_only))
        assert load_scenario(path) == scenario
