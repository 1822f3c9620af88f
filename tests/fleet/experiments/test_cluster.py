"""Runs on a Dask cluster: the bank journals what the local pool journals, a worker with
other code is refused, Ctrl-C stops at once, and the cluster leaves no process or port."""

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from tests.conftest import bound_ports, port_owners, wait_for
from trustfg.fleet.experiments.bank import runner
from trustfg.fleet.experiments.cluster import LAYERS, Cluster, ClusterError
from trustfg.fleet.experiments.workers import parallel

pytestmark = pytest.mark.realtime

SLICE = ["--scenes", "circle-4", "corridor-4", "--seeds", "2", "--methods", "full", "--jobs", "2", "--no-figures"]
MACHINES_OWN = ("wall_s", "cpu_s", "replan_ms_median", "replan_ms_p95", "env")
"""What a journal entry holds of the machine, not of the run (fleet.experiments.bank.recheck.FIELDS
leaves them out too): wall and CPU time and the replans' wall times are measured; ``env``
names the environment of the process that ran it -- a cluster's worker, which on a real
cluster is another machine, and even here differs (Dask starts its workers with
OPENBLAS_NUM_THREADS=1, which a pytest process does not set)."""
WRITTEN_ON = ("code",)
"""The commit of the checkout that wrote the entry (the command's, not a worker's): the
same for every run of one command, but another if a commit lands between two commands."""


def _run_of(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if k not in MACHINES_OWN + WRITTEN_ON}


def _spawned(pid: int) -> set[int]:
    """The worker processes ``pid`` spawned, from any of its threads (multiprocessing's
    resource tracker, which lives as long as its parent, is not one)."""
    children = []
    for thread in Path(f"/proc/{pid}/task").glob("*"):
        try:
            children += [int(c) for c in (thread / "children").read_text().split()]
        except OSError:
            pass
    out = set()
    for child in children:
        try:
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                out.add(child)
        except OSError:
            pass
    return out


def _gone(pids: set[int]) -> bool:
    for pid in pids:
        try:
            if Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z":
                return False
        except OSError:
            pass
    return True


def _ports_of(pids: set[int]) -> set:
    """The listening ports these processes hold."""
    return {port for port, owners in port_owners(bound_ports()).items()
            if any(int(owner.split(":")[0]) in pids for owner in owners)}


def _journal(path: Path) -> dict:
    entries = [json.loads(line) for line in path.read_text().splitlines()]
    return {(e["scene"], e["method"], e["seed"]): e for e in entries}


def test_a_bank_slice_on_a_local_cluster_journals_what_the_local_pool_journals(tmp_path, capsys):
    """2 scenes x 2 seeds of the full pipeline, by the local pool and by a LocalCluster
    of 2 worker processes: the same entries but for MACHINES_OWN and WRITTEN_ON; and a
    cluster bank stopped before its end carries on from its journal as a local one does."""
    assert runner.main([*SLICE, "--out", str(tmp_path / "local")]) == 0
    assert runner.main([*SLICE, "--cluster", "local", "--out", str(tmp_path / "cluster")]) == 0
    assert "cluster local: 2 workers, 2 threads" in capsys.readouterr().err
    local, cluster = _journal(tmp_path / "local" / "runs.jsonl"), _journal(tmp_path / "cluster" / "runs.jsonl")
    assert len(local) == 4 and local.keys() == cluster.keys()
    for key, entry in local.items():
        assert entry.keys() == cluster[key].keys(), key
        assert _run_of(entry) == _run_of(cluster[key]), key
        assert len(cluster[key]["env"]) == 12 and cluster[key]["code"]

    journal = tmp_path / "cluster" / "runs.jsonl"
    kept = journal.read_text().splitlines()[:3]  # as if stopped after three runs
    journal.write_text("".join(line + "\n" for line in kept))
    assert runner.main([*SLICE, "--cluster", "local", "--out", str(tmp_path / "cluster")]) == 0
    assert "3 runs already in" in capsys.readouterr().err
    assert journal.read_text().splitlines()[:3] == kept
    resumed = _journal(journal)
    assert resumed.keys() == local.keys()
    for key, entry in local.items():
        assert _run_of(entry) == _run_of(resumed[key]), key


def test_results_come_in_order_or_as_they_finish_and_the_cluster_leaves_nothing_behind():
    me = os.getpid()
    before = _spawned(me)
    with Cluster("local", 2) as cluster:
        assert list(parallel(abs, range(-6, 0), 2, cluster=cluster)) == [(k, -k) for k in range(-6, 0)]
        assert sorted(parallel(abs, range(-6, 0), 2, ordered=False, cluster=cluster)) == [(k, -k) for k in range(-6, 0)]
        assert len(cluster.workers) == 2
        assert {w.source for w in cluster.workers.values()} == {cluster.here.source}
        workers = _spawned(me) - before
        assert len(workers) == 2
        held = _ports_of(workers | {me})
        assert held  # the scheduler, the nannies and the workers listen
    assert wait_for(lambda: _gone(workers), 10.0), workers
    assert wait_for(lambda: not _ports_of(workers | {me}) & held, 10.0), _ports_of(workers | {me}) & held


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_ctrl_c_or_sigterm_cancels_the_runs_and_stops_the_cluster(tmp_path, stop):
    """Two local workers busy with hour-long runs: Ctrl-C in a terminal (SIGINT to the
    whole process group) or SIGTERM to the command ends it within seconds with
    KeyboardInterrupt, no traceback, and no worker left."""
    script = tmp_path / "long.py"
    script.write_text(textwrap.dedent("""
        import signal, sys, time
        from trustfg.fleet.experiments.cluster import Cluster
        from trustfg.fleet.experiments.workers import parallel
        if __name__ == "__main__":  # the workers are spawned: they import this file
            signal.signal(signal.SIGINT, signal.default_int_handler)  # a terminal's (a background job ignores it)
            try:
                with Cluster("local", 2) as cluster:
                    for _ in parallel(time.sleep, [3600, 3600, 3600], 2, cluster=cluster):
                        pass
            except KeyboardInterrupt:
                print("interrupted", flush=True)
                sys.exit(130)
    """))
    err = tmp_path / "stderr"
    with err.open("w") as sink:
        process = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=sink, text=True,
                                   start_new_session=True)
    workers: set[int] = set()
    try:
        assert wait_for(lambda: "cluster local:" in err.read_text(), 60.0, interval=0.1), err.read_text()
        workers = _spawned(process.pid)
        assert len(workers) == 2
        time.sleep(0.3)  # the runs are under way
        sent = time.monotonic()
        if stop == "ctrl-c":
            os.killpg(process.pid, signal.SIGINT)
        else:
            process.send_signal(signal.SIGTERM)
        out, _ = process.communicate(timeout=30)
        took = time.monotonic() - sent
        assert process.returncode == 130 and "interrupted" in out, err.read_text()
        assert "Traceback" not in err.read_text(), err.read_text()
        assert took < 15, took  # the nanny gives a busy worker 4 s, then kills it
        assert wait_for(lambda: _gone(workers), 10.0), workers
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for pid in workers:  # a cluster that failed the test leaves none behind either
            try:
                if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes():  # ours, not a reused pid
                    os.kill(pid, signal.SIGKILL)
            except (FileNotFoundError, ProcessLookupError):
                pass


def test_a_worker_with_other_code_is_refused(tmp_path):
    """A real worker running a copy of trustfg with one line changed: refused before any
    run, naming both versions."""
    from distributed import LocalCluster

    root = Path(runner.__file__).resolve().parents[3]
    copy = tmp_path / "trustfg"
    copy.mkdir()
    for path in root.glob("*.py"):
        shutil.copy(path, copy)
    for layer in (*LAYERS, "deploy"):
        shutil.copytree(root / layer, copy / layer, ignore=shutil.ignore_patterns("__pycache__"))
    with (copy / "agent" / "planner.py").open("a") as f:
        f.write("# another version of the planner\n")
    with LocalCluster(n_workers=0, processes=True, host="127.0.0.1", dashboard_address=None) as scheduler:
        worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", scheduler.scheduler_address,
                                   "--nthreads", "1", "--no-dashboard"], env=os.environ | {"PYTHONPATH": str(tmp_path)},
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            with Cluster(scheduler.scheduler_address) as cluster, pytest.raises(ClusterError) as refused:
                list(parallel(abs, [-1, -2], 1, cluster=cluster))
            message = str(refused.value)
            assert "runs trustfg" in message and "install the same trustfg on every worker" in message, message
            assert str(cluster.here) in message and message.count("source ") == 2, message
            assert {w.source for w in cluster.workers.values()} != {cluster.here.source}
        finally:
            worker.terminate()
            worker.wait(timeout=30)
