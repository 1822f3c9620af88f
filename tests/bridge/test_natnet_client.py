"""NatNet client: the receiver logic on captured bytes, and the socket layer on loopback
against a scripted fake server (the real simulator server is in tests/mocap_sim)."""

from __future__ import annotations

import socket
import struct
import threading
import time

import pytest

from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V4_1, Frame, MessageId, RigidBody, Version
from trustfg.bridge.natnet_client import (
    FrameReceiver,
    NatNetClient,
    NatNetClientOptions,
    NatNetConnectionError,
    arrival,
)

pytestmark = pytest.mark.realtime

POSE = ((0.5, 0.25, -1.0), (0.0, 0.0, 0.0, 1.0))


def frame_packet(number: int, version: Version = V3_0, bodies=(1, 2)) -> bytes:
    return nn.serialize(Frame(number, tuple(RigidBody(i, *POSE) for i in bodies),
                              number / 120), version)


def server_info(version: Version = V3_0, multicast: bool = False) -> bytes:
    return nn.serialize(nn.ServerInfo("fake", Version(1), version,
                                      nn.ConnectionInfo(1000, 1511, multicast, "239.255.42.99")))


# ---------------------------------------------------------------------------------------
# FrameReceiver: logic without sockets
# ---------------------------------------------------------------------------------------


def test_receiver_takes_the_whole_captured_session(traffic):
    receiver = FrameReceiver(V3_0)
    frames = [d.payload for d in traffic if d.dst_port == 1511]
    for i, packet in enumerate(frames):
        assert receiver.handle(packet, received_s=float(i)) is not None
    stats = receiver.stats()
    assert (stats.received, stats.decoded, stats.dropped, stats.rejected_total) == (518, 518, 0, 0)
    assert stats.last_frame_number == 163251
    sample = receiver.latest(2)
    assert sample.frame_number == 163251 and sample.received_s == 517.0
    assert sample.body.position == pytest.approx((0.17444, 1.44713, -0.73431), abs=5e-6)
    assert receiver.latest(1) is None and set(receiver.latest_all()) == {2}


def test_gaps_are_counted_as_dropped_and_old_frames_as_stale():
    receiver = FrameReceiver(V3_0, restart_threshold=100)
    for number in (1010, 1011, 1014, 1013, 1014, 1020):
        receiver.handle(frame_packet(number), 0.0)
    stats = receiver.stats()
    assert stats.decoded == 4 and stats.dropped == 2 + 5
    assert stats.rejected == {"stale": 2}
    assert receiver.latest(1).frame_number == 1020
    # a jump far back is a server restart, not a stale frame
    assert receiver.handle(frame_packet(1), 0.0) is not None
    assert receiver.stats().last_frame_number == 1


def test_bad_datagrams_are_rejected_by_reason():
    receiver = FrameReceiver(V3_0)
    good = frame_packet(1)
    nan = nn.serialize(Frame(2, (RigidBody(1, (float("nan"), 0.0, 0.0), POSE[1]),), 0.0), V3_0)
    for packet in (good[:20], good[:-1] + b"", good + b"\0", b"\x07", nan,
                   nn.pack_header(7, good[4:] + b"\0\0")):
        assert receiver.handle(packet, 0.0) is None
    assert receiver.stats().rejected == {"size_mismatch": 3, "truncated": 1, "non_finite": 1,
                                         "trailing_bytes": 1}
    assert receiver.handle(good, 0.0) is not None


def test_other_messages_and_the_version_from_server_info():
    receiver = FrameReceiver(None)
    assert receiver.handle(frame_packet(1), 0.0) is None
    assert receiver.stats().rejected == {"no_version": 1}
    receiver.handle(server_info(V4_1), 0.0)
    assert receiver.version == V4_1 and receiver.server_info.app_name == "fake"
    assert receiver.handle(frame_packet(2, V4_1), 0.0) is not None
    pinned = FrameReceiver(V3_0, pinned=True)
    pinned.handle(server_info(V4_1), 0.0)
    assert pinned.version == V3_0
    assert pinned.stats().other == 1


def test_callback_errors_are_counted_and_do_not_stop_the_receiver():
    seen = []

    def callback(frame, received_s):
        seen.append(frame.frame_number)
        if frame.frame_number == 2:
            raise RuntimeError("boom")

    receiver = FrameReceiver(V3_0, callback)
    for number in (1, 2, 3):
        receiver.handle(frame_packet(number), 0.0)
    assert seen == [1, 2, 3] and receiver.stats().callback_errors == 1


def test_wait_for_frames_is_woken_by_the_receiving_thread():
    receiver = FrameReceiver(V3_0)
    assert not receiver.wait_for_frames(1, timeout_s=0.01)
    feeder = threading.Thread(target=lambda: [receiver.handle(frame_packet(n), 0.0)
                                              for n in range(1, 4)])
    feeder.start()
    assert receiver.wait_for_frames(3, timeout_s=5.0)
    feeder.join(5.0)


def test_a_rate_cap_decodes_the_cap_on_average_and_counts_the_rest():
    """120 Hz capped at 50 Hz: 50 frames a second decoded, every second or third; a stream
    slower than the cap is taken whole; no cap takes every frame."""
    def feed(receiver, rate_hz, seconds=2.0):
        taken = [receiver.handle(frame_packet(k + 1), k / rate_hz) is not None for k in range(int(seconds * rate_hz))]
        return taken, receiver.stats()

    taken, stats = feed(FrameReceiver(V3_0, max_rate_hz=50.0), 120.0)
    assert stats.decoded == sum(taken) == 100 and stats.skipped == 240 - 100 and stats.rejected_total == 0
    assert stats.dropped == 0  # frames left undecoded on purpose are not lost frames
    kept = [k for k, t in enumerate(taken) if t]
    assert {b - a for a, b in zip(kept, kept[1:])} <= {2, 3}
    _, stats = feed(FrameReceiver(V3_0, max_rate_hz=50.0), 30.0)
    assert stats.decoded == 60 and stats.skipped == 0
    _, stats = feed(FrameReceiver(V3_0), 120.0)
    assert stats.decoded == 240 and stats.skipped == 0


def test_a_rate_capped_receiver_still_counts_frames_the_network_lost():
    """120 Hz capped at 50 Hz, frames 41-60 lost on the way: 20 dropped, whatever the cap
    left undecoded around them."""
    receiver = FrameReceiver(V3_0, max_rate_hz=50.0)
    for k in range(240):
        if not 40 <= k < 60:
            receiver.handle(frame_packet(k + 1), k / 120.0)
    stats = receiver.stats()
    assert stats.dropped == 20, stats
    assert stats.decoded + stats.skipped == 220


@pytest.mark.parametrize("end_tag", [True, False])
def test_a_skipped_frame_still_tells_that_motives_models_changed(end_tag):
    receiver = FrameReceiver(V3_0, max_rate_hz=50.0)
    assert receiver.handle(frame_packet(1), 0.0) is not None
    payload = nn.encode_frame(Frame(2, (RigidBody(1, *POSE),), 2 / 120, params=0x02), V3_0)
    if not end_tag:
        payload = payload[:-4]  # the SDK's samples do not read the tag; a server may leave it out
    changed = struct.pack("<HH", MessageId.FRAMEOFDATA, len(payload)) + payload
    assert receiver.handle(changed, 1 / 120) is None and receiver.stats().skipped == 1
    assert receiver.models_changed
    quiet = FrameReceiver(V3_0, max_rate_hz=50.0)
    quiet.handle(frame_packet(1), 0.0)
    quiet.handle(frame_packet(2), 1 / 120)
    assert quiet.stats().skipped == 1 and not quiet.models_changed


def test_decode_on_read_gives_the_newest_frame_with_its_own_arrival_time():
    """The command loop's reader: frames kept undecoded as they come; a read decodes the
    newest, the one a receiver decoding every frame would give, stamped when it arrived."""
    receiver = FrameReceiver(V3_0, decode_on_read=True)
    for k in range(1, 6):
        assert receiver.handle(frame_packet(k), k / 120) is None  # held, not decoded
    sample = receiver.latest(2)
    assert sample.frame_number == 5 and sample.received_s == 5 / 120
    stats = receiver.stats()
    assert (stats.received, stats.decoded, stats.skipped, stats.dropped) == (5, 1, 4, 0)
    assert receiver.latest(2) is sample  # nothing new held: nothing decoded again
    for k in (6, 7, 11):  # 8-10 lost on the way
        receiver.handle(frame_packet(k), k / 120)
    assert set(receiver.latest_all()) == {1, 2} and receiver.latest(1).frame_number == 11
    stats = receiver.stats()
    assert (stats.decoded, stats.skipped, stats.dropped) == (2, 6, 3)


def test_decode_on_read_keeps_the_last_good_pose_when_the_newest_datagram_is_bad():
    receiver = FrameReceiver(V3_0, decode_on_read=True)
    receiver.handle(frame_packet(1), 0.0)
    assert receiver.latest(1).frame_number == 1
    good = frame_packet(2)
    receiver.handle(good[:-9], 1 / 120)  # truncated: cut inside its last rigid body
    sample = receiver.latest(1)
    assert sample.frame_number == 1 and sample.received_s == 0.0  # its age is the truth
    assert receiver.stats().rejected_total == 1


def test_decode_on_read_still_hears_that_motives_models_changed():
    receiver = FrameReceiver(V3_0, decode_on_read=True)
    payload = nn.encode_frame(Frame(1, (RigidBody(1, *POSE),), 1 / 120, params=0x02), V3_0)
    receiver.handle(struct.pack("<HH", MessageId.FRAMEOFDATA, len(payload)) + payload, 0.0)
    receiver.handle(frame_packet(2), 1 / 120)  # the change is in the frame nobody decodes
    assert receiver.models_changed


def test_decode_on_read_while_the_socket_thread_feeds_never_goes_back():
    receiver = FrameReceiver(V3_0, decode_on_read=True)
    fed = threading.Event()

    def feed():
        for k in range(1, 3001):
            receiver.handle(frame_packet(k), k / 120)
        fed.set()

    feeder = threading.Thread(target=feed)
    feeder.start()
    seen = []
    while not fed.is_set():
        sample = receiver.latest(1)
        if sample is not None:
            seen.append(sample.frame_number)
    feeder.join(10.0)
    assert receiver.latest(1).frame_number == 3000
    assert seen == sorted(seen) and len(seen) > 10
    stats = receiver.stats()
    assert stats.rejected_total == 0 and stats.dropped == 0 and stats.decoded + stats.skipped == 3000
    assert receiver.wait_for_frames(stats.decoded, timeout_s=0.1)


def test_decode_on_read_takes_no_callback_and_no_rate_cap():
    with pytest.raises(ValueError):
        FrameReceiver(V3_0, lambda frame: None, decode_on_read=True)
    with pytest.raises(ValueError):
        FrameReceiver(V3_0, max_rate_hz=50.0, decode_on_read=True)
    with pytest.raises(ValueError):
        NatNetClientOptions(max_frame_rate_hz=50.0, decode_on_read=True)


def test_options_are_validated():
    with pytest.raises(ValueError, match="natnet_version"):
        NatNetClientOptions(multicast=True, handshake=False)
    with pytest.raises(ValueError):
        NatNetClientOptions(connect_timeout_s=0)
    for rate in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="max_frame_rate_hz"):
            NatNetClientOptions(max_frame_rate_hz=rate)
    NatNetClientOptions(multicast=True, handshake=False, natnet_version=V3_0)


# ---------------------------------------------------------------------------------------
# Socket layer against a scripted server
# ---------------------------------------------------------------------------------------


class FakeServer:
    """A UDP socket on loopback whose thread records what arrives and lets ``reply`` answer."""

    def __init__(self, reply=None):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.address = self.sock.getsockname()
        self.reply = reply or (lambda packet, sender: [])
        self.received: list[tuple[int, bytes, tuple]] = []
        self.cond = threading.Condition()
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5.0)
        self.sock.close()

    def _run(self):
        while not self.stop.is_set():
            try:
                packet, sender = self.sock.recvfrom(65536)
            except socket.timeout:
                continue
            with self.cond:
                self.received.append((nn.peek_message_id(packet), packet, sender))
                self.cond.notify_all()
            for out in self.reply(packet, sender):
                self.sock.sendto(out, sender)

    def wait_for(self, message_id: int, count: int = 1, timeout_s: float = 5.0) -> bool:
        with self.cond:
            return self.cond.wait_for(
                lambda: sum(1 for m, _, _ in self.received if m == message_id) >= count,
                timeout_s)

    def send(self, packet: bytes, to) -> None:
        self.sock.sendto(packet, to)


def unicast_options(server: FakeServer, **kw) -> NatNetClientOptions:
    host, port = server.address
    return NatNetClientOptions(server_address=host, command_port=port, multicast=False,
                               local_address="127.0.0.1", **kw)


def test_handshake_timeout_is_a_clear_error():
    with FakeServer() as server:  # never answers
        options = unicast_options(server, connect_timeout_s=0.3, connect_retry_s=0.1)
        start = time.monotonic()
        with pytest.raises(NatNetConnectionError, match=r"no SERVERINFO .*127\.0\.0\.1"):
            NatNetClient(options).start()
        assert time.monotonic() - start < 2.0
        assert server.wait_for(MessageId.CONNECT, count=2)  # CONNECT is resent
        connect = nn.deserialize(server.received[0][1], V3_0)
        assert connect.client_name == "trustfg" and connect.natnet_version == nn.NEWEST_LAYOUT == Version(4, 2)


def test_unicast_handshake_frames_keepalive_reconnect_and_disconnect(traffic):
    captured = [d.payload for d in traffic if d.dst_port == 1511][:50]

    def reply(packet, sender):
        return [server_info(V3_0)] if nn.peek_message_id(packet) == MessageId.CONNECT else []

    with FakeServer(reply) as server:
        options = unicast_options(server, keepalive_interval_s=0.05, reconnect_after_s=0.3,
                                  requested_version=Version(3, 0))
        with NatNetClient(options) as client:
            assert client.version == V3_0 and client.server_info.app_name == "fake"
            connect = nn.deserialize(server.received[0][1], V3_0)
            assert connect.requested_version == Version(3, 0)
            client_address = server.received[0][2]
            assert client_address == client.local_address
            for packet in captured:
                server.send(packet, client_address)
            assert client.wait_for_frames(50, timeout_s=5.0)
            assert client.latest(2).frame_number == 162734 + 49
            assert server.wait_for(MessageId.KEEPALIVE, count=3)
            # silence: the client connects again (a restarted server forgets its clients)
            assert server.wait_for(MessageId.CONNECT, count=2)
            stats = client.stats()
            assert stats.decoded == 50 and stats.rejected_total == 0
            start = time.monotonic()
        assert time.monotonic() - start < 1.0  # close() joined promptly
        assert server.wait_for(MessageId.DISCONNECT)


def test_arrival_is_the_kernels_stamp_on_the_monotonic_clock():
    stamp = struct.pack("@ll", 1000, 250_000_000)  # wall clock 1000.25 s
    ancillary = [(socket.SOL_SOCKET, 35, stamp)]
    assert arrival(ancillary, mono=50.0, real=1000.75) == pytest.approx(49.5)
    assert arrival(ancillary, mono=50.0, real=1000.0) == 50.0  # a stamp "from the future": now
    assert arrival([], mono=50.0, real=1000.75) == 50.0  # no stamp: the read's time
    assert arrival([(socket.SOL_SOCKET, 29, stamp)], mono=50.0, real=1000.75) == 50.0  # another message


def unicast_server():
    return FakeServer(lambda packet, sender: [server_info(V3_0)]
                      if nn.peek_message_id(packet) == MessageId.CONNECT else [])


def test_pulling_takes_the_waiting_frames_with_their_arrival_and_starts_no_thread():
    """Frames wait in the socket until a read; each keeps the time it arrived, not the
    read's (what a tick takes for the pose's age), and no thread is started for them."""
    with unicast_server() as server:
        threads = threading.active_count()
        taken = []
        with NatNetClient(unicast_options(server, pull=True),
                          on_frame=lambda frame, received_s: taken.append((frame.frame_number, received_s))) as client:
            assert client.thread_id is None and threading.active_count() == threads
            # Linux turns its receive stamps on for the whole host a moment after the
            # first socket asks (a deferred switch): a first frame waits for it.
            server.send(frame_packet(1), client.local_address)
            assert client.wait_for_frames(1, timeout_s=5.0)
            time.sleep(0.2)
            sent = time.monotonic()
            for number in (2, 3, 4):
                server.send(frame_packet(number), client.local_address)
            time.sleep(0.3)
            sample = client.latest(2)
            read = time.monotonic()
            assert sample.frame_number == 4
            assert sent - 0.01 <= sample.received_s <= sent + 0.1  # arrived when sent, 0.3 s before the read
            assert read - sample.received_s >= 0.2
            assert [number for number, _ in taken] == [1, 2, 3, 4]
            assert all(sent - 0.01 <= t <= sent + 0.1 for _, t in taken[1:])
            assert client.stats().decoded == 4 and client.pump() == 0  # nothing more waiting


def test_pulling_with_decode_on_read_decodes_only_the_newest():
    with unicast_server() as server:
        with NatNetClient(unicast_options(server, pull=True, decode_on_read=True)) as client:
            for number in range(1, 11):
                server.send(frame_packet(number), client.local_address)
            assert client.wait_for_frames(1, timeout_s=5.0)
            time.sleep(0.1)
            assert client.latest(1).frame_number == 10
            stats = client.stats()
            assert stats.received >= 10 and stats.skipped == 10 - stats.decoded and stats.dropped == 0


def test_pulling_does_the_unicast_duties_as_it_reads():
    """KEEPALIVE and the reconnect go out from the reads; with nobody reading, nothing does."""
    with unicast_server() as server:
        options = unicast_options(server, pull=True, keepalive_interval_s=0.05, reconnect_after_s=0.3)
        with NatNetClient(options) as client:
            time.sleep(0.4)  # nobody reads
            assert not server.wait_for(MessageId.KEEPALIVE, timeout_s=0.0)
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and not (
                    server.wait_for(MessageId.KEEPALIVE, count=3, timeout_s=0.0)
                    and server.wait_for(MessageId.CONNECT, count=2, timeout_s=0.0)):
                client.stats()  # a read
                time.sleep(0.02)
            assert server.wait_for(MessageId.KEEPALIVE, count=3, timeout_s=0.0)
            assert server.wait_for(MessageId.CONNECT, count=2, timeout_s=0.0)  # silence: connect again
        assert server.wait_for(MessageId.DISCONNECT)


def test_a_pulling_client_survives_a_bad_datagram_and_a_close_under_a_reader():
    with unicast_server() as server:
        client = NatNetClient(unicast_options(server, pull=True)).start()
        server.send(b"\x07\x00\xff\xff", client.local_address)  # a frame header promising more than it has
        server.send(frame_packet(1), client.local_address)
        assert client.wait_for_frames(1, timeout_s=5.0)
        assert client.stats().rejected_total == 1
        reader = threading.Thread(target=lambda: client.wait_for_frames(100, timeout_s=5.0))
        reader.start()
        time.sleep(0.1)
        client.close()
        reader.join(2.0)
        assert not reader.is_alive()  # the waiting reader saw the socket go
        assert client.pump() == 0 and client.latest(1) is not None


@pytest.mark.parametrize("info, match", [(server_info(V3_0, multicast=True), "multicast"),
                                         (server_info(Version(5, 0)), "5.0")])
def test_server_info_that_the_client_cannot_use(info, match):
    with FakeServer(lambda packet, sender: [info]) as server:
        with pytest.raises(NatNetConnectionError, match=match):
            NatNetClient(unicast_options(server, connect_timeout_s=2.0)).start()


def test_pinned_version_overrides_the_server():
    def reply(packet, sender):
        return [server_info(V4_1)] if nn.peek_message_id(packet) == MessageId.CONNECT else []

    with FakeServer(reply) as server:
        with NatNetClient(unicast_options(server, natnet_version=V3_0)) as client:
            assert client.version == V3_0
            server.send(frame_packet(1, V3_0), client.local_address)
            assert client.wait_for_frames(1, timeout_s=5.0)


@pytest.mark.parametrize("pull", [False, True])
def test_multicast_without_handshake_replays_the_captured_session(traffic, multicast_group, pull):
    group, port = multicast_group
    frames = [d.payload for d in traffic if d.dst_port == 1511]
    options = NatNetClientOptions(multicast=True, handshake=False, natnet_version=V3_0,
                                  multicast_group=group, data_port=port,
                                  local_address="127.0.0.1", pull=pull)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
    sender.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
    try:
        # two car processes on one host: both get every datagram
        with NatNetClient(options) as a, NatNetClient(options) as b:
            for start in range(0, len(frames), 64):
                for packet in frames[start:start + 64]:
                    sender.sendto(packet, (group, port))
                end = min(start + 64, len(frames))
                assert a.wait_for_frames(end, 5.0) and b.wait_for_frames(end, 5.0)
            for client in (a, b):
                stats = client.stats()
                assert stats.decoded == 518 and stats.dropped == 0
                assert stats.last_frame_number == 163251
    finally:
        sender.close()


def test_joining_a_bad_multicast_interface_is_a_clear_error():
    options = NatNetClientOptions(multicast=True, handshake=False, natnet_version=V3_0,
                                  multicast_group="239.255.42.99", data_port=0,
                                  local_address="203.0.113.7")  # not ours
    with pytest.raises(NatNetConnectionError, match="cannot join multicast group"):
        NatNetClient(options).start()
