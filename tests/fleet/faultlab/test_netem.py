"""The delaying TCP and UDP relays of the fault suite (no root needed)."""

import json
import os
import socket
import threading
import time

import pytest

from trustfg.fleet.faultlab.netem import DatagramRelay, DelayRelay, Lab, available

pytestmark = pytest.mark.realtime


@pytest.fixture
def echo_server():
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    stop = threading.Event()

    def serve():
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            with conn:
                while data := conn.recv(4096):
                    conn.sendall(data)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname()
    stop.set()
    thread.join(2)
    server.close()


def test_relay_delays_each_way_in_order(echo_server):
    relay = DelayRelay("127.0.0.1", echo_server, delay_s=0.05, jitter_s=0.02, seed=1)
    relay.start()
    try:
        with socket.create_connection(relay.address, timeout=5) as s:
            rtts, received = [], b""
            for i in range(20):
                sent = time.monotonic()
                s.sendall(b"%03d" % i)
                while len(received) < 3 * (i + 1):
                    received += s.recv(64)
                rtts.append(time.monotonic() - sent)
        assert received == b"".join(b"%03d" % i for i in range(20))  # nothing reordered or lost
        assert min(rtts) >= 2 * 0.03 - 0.005  # both directions held at least 30 ms
        assert max(rtts) < 1.0  # and let them go (the upper bound is a sanity check, not a timing target)
    finally:
        relay.close()


@pytest.fixture
def udp_echo():
    server = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    server.bind(("127.0.0.1", 0))
    server.settimeout(0.2)
    stop = threading.Event()
    sources = set()

    def serve():
        while not stop.is_set():
            try:
                data, source = server.recvfrom(4096)
            except TimeoutError:
                continue
            sources.add(source)
            server.sendto(data, source)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield server.getsockname(), sources
    stop.set()
    thread.join(2)
    server.close()


def test_datagram_relay_delays_each_way_in_order_one_source_per_client(udp_echo):
    target, sources = udp_echo
    relay = DatagramRelay("127.0.0.1", target, delay_s=0.05, jitter_s=0.02, seed=1)
    relay.start()
    clients = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    try:
        for client in clients:
            client.settimeout(2)
        sent = time.monotonic()
        for i in range(20):  # a burst: each datagram's delay is drawn anew, yet none overtakes
            clients[0].sendto(b"%03d" % i, relay.address)
        echoed = [clients[0].recvfrom(64) for _ in range(20)]
        rtt = time.monotonic() - sent
        assert [data for data, _ in echoed] == [b"%03d" % i for i in range(20)]
        assert {source for _, source in echoed} == {relay.address}  # answers come from the relay
        assert rtt >= 2 * 0.03 - 0.005  # both directions held at least 30 ms
        clients[1].sendto(b"x", relay.address)
        assert clients[1].recvfrom(64)[0] == b"x"
        assert len(sources) == 2  # the target saw each client as its own peer
    finally:
        for client in clients:
            client.close()
        relay.close()
    assert relay.front.fileno() == -1  # closed with the relay


def test_lab_needs_root_or_says_why():
    reason = available()
    assert reason is None or "root" in reason or "installed" in reason
    if reason is None:
        with Lab([1]) as lab:
            assert lab.car_ip(1).startswith("10.77.")


@pytest.mark.skipif(available() is not None, reason=str(available()))
def test_a_killed_runs_lab_is_swept_and_a_live_one_is_not():
    """A test run killed before its lab's __exit__ leaves namespaces behind, which would fail
    the next run's leftover check: the next sweep removes them, never a live lab's."""
    import signal
    import subprocess
    import sys

    from trustfg.fleet.faultlab import netem

    script = ("import sys, time\nfrom trustfg.fleet.faultlab.netem import Lab\nlab = Lab([1, 2]).__enter__()\n"
              "print(lab.tag, flush=True)\ntime.sleep(60)\n")
    child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    try:
        tag = child.stdout.readline().strip()
        assert len(tag) == 4, tag
        with Lab([3]) as live:
            def namespaces(t):
                listing = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
                return sorted(line.split()[0] for line in listing.splitlines() if line.startswith(f"tfg{t}c"))

            assert namespaces(tag) == [f"tfg{tag}c1", f"tfg{tag}c2"]
            assert netem.sweep_stale() == []  # its maker still runs
            assert namespaces(tag) != []
            child.send_signal(signal.SIGKILL)
            child.wait(10)
            assert netem.sweep_stale() == [tag]
            assert namespaces(tag) == []
            assert not (netem.OWNERS / f"{tag}.owner").exists()
            assert subprocess.run(["ip", "link", "show", f"tfg{tag}br"], capture_output=True).returncode != 0
            assert namespaces(live.tag) == [f"tfg{live.tag}c3"]  # the live lab is untouched
        assert namespaces(live.tag) == [] and not (netem.OWNERS / f"{live.tag}.owner").exists()
    finally:
        child.kill()
        child.wait(10)
        netem.sweep_stale()


def test_an_unreadable_owner_record_counts_as_stale(tmp_path, monkeypatch):
    from trustfg.fleet.faultlab import netem

    monkeypatch.setattr(netem, "OWNERS", tmp_path)
    (tmp_path / "abcd.owner").write_text("{not json")
    assert netem._owner_alive(tmp_path / "abcd.owner") is False
    (tmp_path / "abce.owner").write_text(json.dumps({"pid": os.getpid(), "started": netem._started(os.getpid())}))
    assert netem._owner_alive(tmp_path / "abce.owner") is True
    (tmp_path / "abcf.owner").write_text(json.dumps({"pid": os.getpid(), "started": -1}))  # the pid reused
    assert netem._owner_alive(tmp_path / "abcf.owner") is False
