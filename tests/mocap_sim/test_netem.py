"""The delaying TCP and UDP relays of the fault suite (no root needed)."""

import socket
import threading
import time

import pytest

from trustfg.fleet.netem import DatagramRelay, DelayRelay, Lab, available


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
