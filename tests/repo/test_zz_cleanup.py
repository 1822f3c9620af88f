"""After the whole suite: no trustfg process and no port the tests opened is left."""

import pytest

from tests.conftest import (
    BOUND_AT_START,
    FIRST_HELD_AFTER,
    bound_ports,
    left_behind,
    other_workers_done,
    port_owners,
    trustfg_processes,
    wait_for,
)

pytestmark = pytest.mark.realtime


def test_nothing_is_left_behind(pytestconfig):
    # under xdist, after the other worker's last test too (its group may end after this one)
    assert wait_for(lambda: other_workers_done(pytestconfig), 1800.0, interval=0.5), "another xdist worker never finished"
    assert wait_for(lambda: not left_behind(), 10.0), left_behind()
    left = lambda: bound_ports() - BOUND_AT_START  # noqa: E731
    assert wait_for(lambda: not left(), 10.0), {port: (owners, "first held by pytest after " + FIRST_HELD_AFTER.get(port, "-"))
                                                for port, owners in port_owners(left()).items()}
    assert not fault_namespaces(), fault_namespaces()


def fault_namespaces() -> list[str]:
    """Network namespaces the fault suite made (they are named tfg...)."""
    import shutil
    import subprocess

    if shutil.which("ip") is None:
        return []
    listing = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    return [line.split()[0] for line in listing.splitlines() if line.startswith("tfg")]


def test_the_check_sees_a_leftover_process_and_port():
    import socket
    import subprocess
    import sys

    probe = subprocess.Popen([sys.executable, "-c", "import time, sys; time.sleep(60)", "-m trustfg"])
    sock = socket.socket()
    sock.bind(("127.0.0.1", 0))
    sock.listen()
    try:
        assert wait_for(lambda: any(line.startswith(f"{probe.pid}:") for line in trustfg_processes()), 5.0)
        assert any(line.startswith(f"{probe.pid}:") for line in left_behind())  # the suite's own
        assert ("tcp", sock.getsockname()[1]) in bound_ports() - BOUND_AT_START
    finally:
        probe.kill()
        probe.wait()
        sock.close()


def test_the_check_sees_a_leftover_command_loop_by_its_name():
    """A car process's command loop is spawned by multiprocessing (its command line says
    nothing of trustfg); it names itself (fleet.car.velocity_loop.name_process)."""
    import subprocess
    import sys

    probe = subprocess.Popen([sys.executable, "-c", "import time\nfrom trustfg.fleet.car.velocity_loop import name_process\n"
                              "name_process('trustfg-cmd-9')\ntime.sleep(60)"])
    try:
        assert wait_for(lambda: any(line.startswith(f"{probe.pid}: trustfg-cmd-9") for line in trustfg_processes()), 10.0)
    finally:
        probe.kill()
        probe.wait()
