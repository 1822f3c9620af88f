"""A wheel works on its own: built from this tree, installed into a fresh venv, run from
an empty directory, with nothing but ``trustfg`` at the top of site-packages.

The fresh venv has no pip; its dependencies come from this test's own environment
through one .pth line (a directory a .pth names is only put on the path: its own .pth
files, such as the editable install's finder, are not run), so the wheel is the only
trustfg it can import.
"""

import csv
import json
import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

pytestmark = pytest.mark.realtime

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    work = tmp_path_factory.mktemp("wheel")
    # Build from a copy of the sources alone: a build/ folder left in a working tree would
    # otherwise be reused by setuptools.
    source = work / "source"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "build", "runs", "__pycache__", "*.egg-info", ".pytest_cache", ".hypothesis"))
    built = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(work / "dist"),
                            str(source)], capture_output=True, text=True, timeout=600)
    assert built.returncode == 0, built.stderr
    (wheel,) = (work / "dist").glob("trustfg-*.whl")
    venv = work / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               capture_output=True, text=True, check=True).stdout.strip())
    installed = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps",
                                "--no-index", "-q", str(wheel)], capture_output=True, text=True, timeout=300)
    assert installed.returncode == 0, installed.stderr
    (site / "zz_test_dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    empty = work / "empty"
    empty.mkdir()
    return venv, site, empty


def run(venv: Path, cwd: Path, *argv: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}:{env.get('PATH', '')}"
    return subprocess.run(list(argv), cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_only_trustfg_is_installed_at_the_top_level(installed):
    venv, site, _ = installed
    (dist_info,) = site.glob("trustfg-*.dist-info")
    with open(dist_info / "RECORD", newline="") as f:
        tops = {Path(row[0]).parts[0] for row in csv.reader(f)}
    assert tops == {"trustfg", dist_info.name, ".."}, tops  # ".." : the console script in bin/
    assert (venv / "bin" / "trustfg").exists()


def test_the_wheel_runs_from_an_empty_directory(installed):
    venv, site, empty = installed
    where = run(venv, empty, "python", "-c", "import trustfg, trustfg.agent; print(trustfg.__file__)")
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).is_relative_to(site), where.stdout  # the wheel, not this tree
    shipped = run(venv, empty, "python", "-c", (
        "import json; from trustfg.agent.scenario_files import shipped, load_scenario;"
        "print(json.dumps({n: len(load_scenario(n).cars) for n in shipped()}))"))
    assert shipped.returncode == 0, shipped.stderr
    assert {"intersection", "intersection-8", "lab"} <= set(json.loads(shipped.stdout))
    experiment = run(venv, empty, "trustfg", "experiment", "proximity", "--seeds", "1", "--jobs", "1",
                     "--no-figures", "--out", "out")
    assert experiment.returncode == 0, experiment.stderr
    assert (empty / "out" / "proximity" / "metrics.json").exists()


@pytest.mark.slow
def test_the_main_job_runs_from_the_wheel(installed):
    venv, _, empty = installed
    sim = run(venv, empty, "trustfg", "sim", "--no-dashboard", "--out", "sim", timeout=240)
    assert sim.returncode == 0, sim.stdout[-2000:] + sim.stderr[-2000:]
    summary = json.loads((empty / "sim" / "summary.json").read_text())
    assert all(summary["reached_goal"]) and not summary["breaches"] and not summary["crashed"]
