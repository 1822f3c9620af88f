"""The fleet split over two hosts that reach each other only through a Zenoh router.

Two network namespaces act as two car computers (cars 1 and 2 on one, 3 and 4 on the
other); nftables drops every packet between them. mocap-sim, the operator and a
``trustfg router`` live in the root namespace, the lab network both hosts reach. Every
car process is a Zenoh client of the router. Needs root: skipped with the reason otherwise.
"""

import json
import subprocess
import sys

import pytest

from trustfg.fleet.bus.router import through_router
from trustfg.fleet.faultlab import netem
from trustfg.fleet.launch.launcher import loopback_fleet, run
from trustfg.fleet.launch.ports import free_port

pytestmark = [pytest.mark.faults, pytest.mark.realtime,
              pytest.mark.skipif(netem.available() is not None, reason=str(netem.available()))]

HOSTS = {1: 1, 2: 1, 3: 2, 4: 2}


def reaches(lab, host, address, port):
    """Whether a TCP connection from ``host``'s namespace to address:port is answered
    (accepted or refused) within a second; False if the packets are dropped."""
    probe = ("import socket,sys\ntry: socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=1.0)\n"
             "except ConnectionRefusedError: pass\nexcept OSError: sys.exit(1)")
    argv = lab.in_host(host, [sys.executable, "-c", probe, address, str(port)])
    return subprocess.run(argv, capture_output=True, timeout=10).returncode == 0


@pytest.fixture
def router(tmp_path):
    def start(address):
        port = free_port()
        process = subprocess.Popen([sys.executable, "-m", "trustfg", "router", "--listen", f"tcp/{address}:{port}"],
                                   stdout=subprocess.PIPE, stderr=open(tmp_path / "router.log", "w"), text=True)
        started.append(process)
        assert process.stdout.readline().strip() == "READY", (tmp_path / "router.log").read_text()
        return f"tcp/{address}:{port}"
    started: list[subprocess.Popen] = []
    yield start
    for process in started:
        process.terminate()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        process.stdout.close()


def test_a_fleet_split_over_two_hosts_completes_through_a_router(intersection, router, tmp_path):
    with netem.Lab([c.id for c in intersection.cars], hosts=HOSTS) as lab:
        lab.isolate_hosts()
        # The hosts cannot reach each other; both reach the lab network.
        assert not reaches(lab, 1, lab.car_ip(3), 9)
        assert not reaches(lab, 2, lab.car_ip(1), 9)
        assert reaches(lab, 1, lab.infra_ip, free_port()) and reaches(lab, 2, lab.infra_ip, free_port())
        endpoint = router(lab.infra_ip)
        fleet = through_router(loopback_fleet(intersection, None, None, 0.0, infra_ip=lab.infra_ip,
                                              car_ips=lab.car_ips()), endpoint)
        summary = run(fleet, tmp_path / "run", seed=5, wrap=lab.wrap, infra_ip=lab.infra_ip)
    assert summary["crashed"] == [] and summary["breaches"] == [], summary
    assert all(summary["reached_goal"]), summary["reached_goal"]
    # Plans crossed between the hosts: every car planned against the cars of the other host
    # (its status reports how old the plan it holds from each peer is).
    status = {}
    with open(tmp_path / "run" / "messages.jsonl") as f:
        for line in f:
            record = json.loads(line)
            if record["kind"] == "status" and "message" in record:
                status[record["sender"]] = record["message"]
    for car, host in HOSTS.items():
        peers_abroad = [peer for peer, h in HOSTS.items() if h != host]
        counters = status[car]["counters"]
        assert all(f"plan_age_ms_{peer}" in counters for peer in peers_abroad), (car, counters)
