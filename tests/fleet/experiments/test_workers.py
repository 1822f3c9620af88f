"""Runs in worker processes: results in order or as they finish, and Ctrl-C stops at once."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from trustfg.fleet.experiments.workers import parallel

pytestmark = pytest.mark.realtime


def _square(task: int) -> int:
    time.sleep(0.01 * (task % 3))  # finish out of order
    return task * task


@pytest.mark.parametrize("jobs", [1, 2])
def test_results_come_with_their_tasks_in_order(jobs):
    assert list(parallel(_square, range(12), jobs)) == [(k, k * k) for k in range(12)]


def test_results_come_as_they_finish_when_order_does_not_matter():
    assert sorted(parallel(_square, range(12), 2, ordered=False)) == [(k, k * k) for k in range(12)]


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(c) for c in f.read().split()]
    except FileNotFoundError:
        return []


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_ctrl_c_or_sigterm_stops_the_runs_under_way_and_leaves_no_worker(tmp_path, signum):
    """Two workers busy with hour-long runs: SIGINT to the parent (as a terminal sends it)
    or SIGTERM (as kill does) ends the parent within seconds, with KeyboardInterrupt, and
    no worker survives nor prints a traceback."""
    script = tmp_path / "long.py"
    script.write_text(textwrap.dedent("""
        import signal, sys, time
        signal.signal(signal.SIGINT, signal.default_int_handler)  # a terminal's (a background job ignores it)
        from trustfg.fleet.experiments.workers import parallel
        try:
            for _ in parallel(time.sleep, [3600, 3600, 3600], 2):
                pass
        except KeyboardInterrupt:
            print("interrupted", flush=True)
            sys.exit(130)
    """))
    process = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 30
        while len(_children(process.pid)) < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
        workers = _children(process.pid)
        assert len(workers) == 2
        time.sleep(0.3)  # the runs are under way
        sent = time.monotonic()
        process.send_signal(signum)
        out, err = process.communicate(timeout=20)
        assert process.returncode == 130 and "interrupted" in out, err
        assert "Traceback" not in err, err
        assert time.monotonic() - sent < 10
        for pid in workers:
            assert not os.path.exists(f"/proc/{pid}") or "Z" in open(f"/proc/{pid}/stat").read().split()[2]
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for pid in workers:  # a pool that failed the test leaves none behind either
            try:
                if str(script).encode() in open(f"/proc/{pid}/cmdline", "rb").read():  # ours, not a reused pid
                    os.kill(pid, signal.SIGKILL)
            except (FileNotFoundError, ProcessLookupError):
                pass
