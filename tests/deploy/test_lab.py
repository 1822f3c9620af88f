"""The shipped deploy files agree with each other and with docs/lab-guide.md: the systemd
unit installs with any virtual environment, user and config; the lab configs load, switch
the deadman on, name the files they are and the lab guide."""

import shutil
import subprocess

import pytest

from tests.conftest import ROOT
from trustfg.agent.scenario_files import load_scenario

pytestmark = pytest.mark.realtime

INSTALL = ROOT / "deploy" / "systemd" / "install.sh"


def test_the_unit_installs_with_the_venv_user_and_config_asked_for(tmp_path):
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "trustfg").write_text("#!/bin/sh\n")
    (venv / "bin" / "trustfg").chmod(0o755)
    config = tmp_path / "fleet-secure.toml"
    config.write_text((ROOT / "deploy" / "lab" / "fleet-secure.toml").read_text())
    done = subprocess.run(["bash", str(INSTALL), "--venv", str(venv), "--user", "labcar", "--config", str(config),
                           "--dry-run"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    unit = done.stdout
    assert f"ExecStart={venv}/bin/trustfg car --id %i --config ${{TRUSTFG_CONFIG}}" in unit
    assert "User=labcar" in unit and "Group=labcar" in unit
    assert f"TRUSTFG_CONFIG={config}" in unit
    assert "/opt/trustfg" not in unit and "@" not in unit.replace("%i", "").split("[Unit]")[1].split("\n#")[0]


@pytest.mark.parametrize("argv, says", [
    ([], "required"), (["--venv", "/nonexistent", "--user", "u", "--config", "x"], "no folder"),
    (["--fly"], "unknown argument"),
])
def test_install_errors_are_one_line(argv, says):
    done = subprocess.run(["bash", str(INSTALL), *argv], capture_output=True, text=True)
    assert done.returncode == 2 and says in done.stderr and len(done.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("name", ["fleet", "fleet-secure"])
def test_the_lab_configs_load_with_the_deadman_on_and_name_themselves(name):
    fleet = load_scenario(f"lab/{name}")
    assert fleet.operator.deadman_s > 0 and not fleet.control.start_timeout_s
    text = (ROOT / "deploy" / "lab" / f"{name}.toml").read_text()
    assert f"deploy/lab/{name}.toml" in text.split("\n\n")[0].replace("\n# ", " ")
    assert "docs/lab-guide.md" in text


def test_the_secure_lab_uses_tls_everywhere():
    fleet = load_scenario("lab/fleet-secure")
    endpoints = [*fleet.bus.connect, *(e for car in fleet.cars for e in car.listen)]
    assert endpoints and all(e.startswith("tls/") for e in endpoints) and fleet.bus.zenoh_config


def test_systemd_accepts_the_rendered_unit(tmp_path):
    analyze = shutil.which("systemd-analyze")
    if analyze is None:
        pytest.skip("systemd-analyze is not installed here")
    venv = tmp_path / "venv"
    (venv / "bin").mkdir(parents=True)
    (venv / "bin" / "trustfg").write_text("#!/bin/sh\n")
    (venv / "bin" / "trustfg").chmod(0o755)
    (tmp_path / "fleet.toml").write_text("")
    done = subprocess.run(["bash", str(INSTALL), "--venv", str(venv), "--user", "root", "--config",
                           str(tmp_path / "fleet.toml"), "--dry-run"], capture_output=True, text=True, check=True)
    unit = tmp_path / "trustfg-car@1.service"
    unit.write_text(done.stdout.split("# /etc/trustfg/car.env")[0])
    verified = subprocess.run([analyze, "verify", str(unit)], capture_output=True, text=True, timeout=60)
    assert verified.returncode == 0 and not verified.stderr.strip(), verified.stderr
