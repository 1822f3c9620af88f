import json
import os
import subprocess
import sys


def test_experiment_command_writes_metrics_and_figures(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "trustfg", "experiment", "lab", "--seeds", "1", "--jobs", "2",
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


def test_studies_write_their_tables(tmp_path):
    """The adversaries experiment and the transparency sweep, one seed each, end to end."""
    done = subprocess.run(
        [sys.executable, "-m", "trustfg", "experiment", "adversaries", "--seeds", "1", "--scenes", "intersection",
         "--attacks", "displaced", "--variants", "on", "off", "--held-out", "--jobs", "2", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "adversaries" / "metrics.json").read_text())
    cell = report["summary"]["intersection"]["displaced"]["on"]
    assert cell["runs"] == 1 and cell["breach_rate"]["ci"] is not None
    assert "| intersection | displaced | off |" in (tmp_path / "adversaries" / "table.md").read_text()
    done = subprocess.run(
        [sys.executable, "-m", "trustfg", "experiment", "transparency-sweep", "--seeds", "1", "--scene", "intersection",
         "--misinformation", "0.4", "--gains", "2", "--jobs", "2", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads((tmp_path / "transparency-sweep" / "metrics.json").read_text())
    assert set(report["summary"]["0.4"]) == {"off", "on@2", "wide@2"}
    bad = subprocess.run([sys.executable, "-m", "trustfg", "experiment", "adversaries", "--scenes", "nowhere"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "nowhere" in bad.stderr and "Traceback" not in bad.stderr


def test_a_trustfg_process_runs_one_blas_thread():
    """numpy's and scipy's OpenBLAS would each start a thread per core in every car process."""
    code = ("import os, sys\n"
            "from trustfg.cli import main\n"
            "try:\n    main(['car', '--help'])\nexcept SystemExit:\n    pass\n"
            "import scipy.linalg  # scipy's own OpenBLAS too\n"
            "print(len(os.listdir('/proc/self/task')), file=sys.stderr)\n")
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip().splitlines()[-1] == "1"
