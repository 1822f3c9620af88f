"""trustfg config: the reference it writes, and a run's effective configuration, which
loads back into the Scenario it was printed from with every key written out."""

import dataclasses
import tomllib
from pathlib import Path

import pytest

from trustfg.agent.config import AttackConfig, Obstacle, reference
from trustfg.agent.config.command_line import main
from trustfg.agent.config.toml_text import effective_toml
from trustfg.agent.scenario_files import load_scenario, scenario_from_dict
from trustfg.cli import main as trustfg

ROOT = Path(__file__).resolve().parents[3]
SHIPPED = sorted([*(ROOT / "deploy" / "scenarios").glob("*.toml"), *(ROOT / "deploy" / "lab").glob("*.toml")])


def test_every_shipped_folder_has_scenes():
    assert {p.parent.name for p in SHIPPED} == {"scenarios", "lab"} and len(SHIPPED) >= 10


def test_reference_writes_the_page_or_prints_it(tmp_path, capsys):
    out = tmp_path / "docs" / "configuration.md"
    assert main(["reference", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == reference.render()
    capsys.readouterr()
    assert main(["reference"]) == 0
    assert capsys.readouterr().out == reference.render()


def shown(capsys, source: str) -> str:
    capsys.readouterr()
    assert main(["show", "--scenario", source]) == 0
    return capsys.readouterr().out


def written_keys(obj) -> set[str]:
    return {f.name for f in dataclasses.fields(obj) if getattr(obj, f.name) is not None}


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_show_prints_every_key_and_loads_back_equal(path, capsys):
    scenario = load_scenario(path)
    text = shown(capsys, str(path))
    data = tomllib.loads(text)
    assert scenario_from_dict(data) == scenario
    for f in dataclasses.fields(scenario):
        value = getattr(scenario, f.name)
        if dataclasses.is_dataclass(value):
            assert set(data[f.name]) == written_keys(value), f.name
    for table, car in zip(data["cars"], scenario.cars):
        assert set(table) == written_keys(car)
    for table in data["world"].get("obstacles", []):
        assert set(table) == written_keys(Obstacle())
    assert text.startswith(f"# The effective configuration of {path}")


def test_show_takes_a_shipped_name_and_fills_in_what_the_file_leaves_out(capsys):
    """intersection.toml sets no [planner]; lab/fleet sets operator.deadman_s."""
    data = tomllib.loads(shown(capsys, "intersection"))
    assert data["planner"]["support_states"] == 21 and data["vehicle"]["max_speed_mps"] == 0.8
    assert tomllib.loads(shown(capsys, "lab/fleet"))["operator"]["deadman_s"] == 1.0


def test_keys_that_are_not_set_are_named_and_set_ones_round_trip(intersection):
    """TOML has no null: a None is left out and named in the header; the same keys set, and
    an attack with parameters, come back as they were."""
    cars = list(intersection.cars)
    cars[0] = dataclasses.replace(cars[0], attack=AttackConfig("bias+slander", {"bias_m": 0.1, "target": 3.0}),
                                  start_heading_rad=1.5)
    world = dataclasses.replace(intersection.world, obstacles=(
        Obstacle(kind="polygon", points=((0.0, 0.0), (0.5, 0.0), (0.0, 0.5))),))
    scenario = dataclasses.replace(intersection, cars=tuple(cars), world=world)
    text = effective_toml(scenario, "x.toml")
    assert scenario_from_dict(tomllib.loads(text)) == scenario
    header = "".join(line[1:] for line in text.splitlines() if line.startswith("#"))
    assert "sim.replan_phase_max_s" in " ".join(header.split())
    assert "cars.start_heading_rad (cars 2, 3, 4)" in " ".join(header.split())
    assert "cars.attack (cars 2, 3, 4)" in " ".join(header.split())
    everything_set = dataclasses.replace(scenario, sim=dataclasses.replace(scenario.sim, replan_phase_max_s=0.0))
    assert "sim.replan_phase_max_s" not in effective_toml(everything_set, "x.toml").split("\n\n")[0]


def test_a_bad_scenario_is_one_line_and_exit_status_2(capsys, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[planner]\nsupport_states = "many"\n')
    for source in (str(bad), "no-such-scene"):
        assert main(["show", "--scenario", source]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("trustfg config: ") and source in err


def test_usage_errors_are_one_line(capsys):
    for argv in (["show"], ["shw"], ["reference", "--ou", "x"]):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2
        assert capsys.readouterr().err.count("\n") == 1


def test_trustfg_runs_it_as_a_command(capsys):
    assert trustfg(["config", "show", "--scenario", "circle-4"]) == 0
    assert tomllib.loads(capsys.readouterr().out)["name"] == "circle-4"
