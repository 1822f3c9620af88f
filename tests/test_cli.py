import json
import subprocess
import sys


def test_experiment_command_writes_metrics_and_figures(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "trustfg", "experiment", "lab", "--seeds", "1", "--jobs", "1",
         "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "min distance matrix A" in done.stdout and "min distance matrix B" in done.stdout
    report = json.loads((tmp_path / "lab" / "metrics.json").read_text())
    assert report["experiment"] == "lab" and report["seeds"] == [0]
    assert set(report["variants"]) == {"A", "on", "off"}
    run = report["variants"]["on"][0]
    assert run["liar_id"] == 1 and len(run["liar_min_distance"]) == 3
    for name in ("trajectories.png", "min_distance.png", "acceleration.png", "trust.png"):
        assert (tmp_path / "lab" / name).stat().st_size > 10_000
    assert "[lab]" in done.stderr  # progress


def test_unknown_command_and_bad_arguments():
    bad = subprocess.run([sys.executable, "-m", "trustfg", "fly"], capture_output=True, text=True)
    assert bad.returncode == 2 and "unknown command" in bad.stderr
    bad = subprocess.run([sys.executable, "-m", "trustfg", "experiment", "proximity", "--seeds", "0"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "--seeds" in bad.stderr
