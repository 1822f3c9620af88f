"""The README's two set-up commands are the contract with new users and CI."""

import re
from pathlib import Path

import pytest

pytestmark = pytest.mark.realtime

ROOT = Path(__file__).resolve().parents[2]


def commands():
    text = (ROOT / "README.md").read_text()
    section = text.split("## Set up and run")[1].split("\n## ")[0]
    return [line for block in re.findall(r"```sh\n(.*?)```", section, re.S)
            for line in block.splitlines() if line and not line.startswith("#")]


def test_readme_has_exactly_two_setup_commands_and_ci_runs_the_test_one():
    main_job, tests = commands()
    assert "pip install" in main_job and "trustfg" in main_job
    assert "pytest" in tests
    ci = (ROOT / ".ci" / "run").read_text().splitlines()
    assert tests in ci


def test_shipped_deploy_configs_load():
    import zenoh

    from trustfg.agent.scenario_files import load_scenario

    for name in ("fleet.toml", "fleet-secure.toml"):
        fleet = load_scenario(ROOT / "deploy" / "lab" / name)
        assert len(fleet.cars) == 4 and all(car.link and car.listen for car in fleet.cars)
    for path in (ROOT / "deploy" / "zenoh").glob("*.json5"):
        zenoh.Config.from_file(str(path))
