"""How often Zenoh peers that open their sessions at once lose a subscription or a token.

    python benchmarks/bench_zenoh_start.py [--starts 50] [--peers 4] [--seconds 6] [--dial all|lower]
                                           [--watch silent|behind] [--tcp-only]

Bare Zenoh sessions, no trustfg code on the wire: each start opens ``--peers`` peers in
their own processes on loopback (a TCP and a UDP ``?rel=0`` endpoint each, multicast
scouting off; ``--dial lower``: only the higher id dials). Each subscribes to every peer's
plans (advanced subscriber, as fleet.bus.session) and status, publishes both every 0.1 s,
and declares a liveliness token. A start is *lost* when some peer heard nothing of some
kind of another in the last second; a token is *missed* when a peer never saw it though it
hears that peer. ``--watch`` adds fleet.bus.session's rule (``silent_kinds``; ``silent``:
without its plans-behind part); "plan silence" is the longest a peer's plans went unheard.
Load the cores to see more losses. Results: docs/results/zenoh-liveliness.md.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import socket
import time

import zenoh
import zenoh.ext as zext

from trustfg.fleet.bus.session import FREQUENT, RESUBSCRIBE_EVERY_S, silent_kinds
from trustfg.fleet.launch.ports import free_port

KINDS = ("plan", "status")



def config(listen: tuple[str, ...], connect: tuple[str, ...]) -> zenoh.Config:
    c = zenoh.Config()
    for path, value in (("mode", "peer"), ("scouting/multicast/enabled", False), ("scouting/delay", 0),
                        ("transport/unicast/max_links", 4), ("listen/endpoints", list(listen)),
                        ("connect/endpoints", [e for e in connect if e not in listen])):
        c.insert_json5(path, json.dumps(value))
    return c


def peer(me: int, peers: int, listen, connect, prefix: str, seconds: float, watch: str, out) -> None:
    session = zenoh.open(config(listen, connect))
    heard: dict[tuple[int, str], float] = {}
    first: dict[int, float] = {}
    silence: dict[int, float] = {}  # the longest gap between a peer's plans after the first second
    started = time.monotonic()

    def note_silence(sender: int, now: float) -> None:
        """How long the sender's plans have gone unheard at ``now`` (after the first second)."""
        since = max(heard.get((sender, "plan"), started), started + 1.0)
        silence[sender] = max(silence.get(sender, 0.0), now - since)

    def on_sample(sample: zenoh.Sample) -> None:
        parts = str(sample.key_expr).split("/")
        sender, kind, now = int(parts[1]), parts[2], time.monotonic()
        if kind == "plan":
            note_silence(sender, now)
        heard[(sender, kind)] = now
        first.setdefault(sender, now)

    def subscribe(kind: str):
        if kind == "plan":
            return zext.declare_advanced_subscriber(
                session, f"{prefix}/*/plan", on_sample, history=zext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                recovery=zext.RecoveryConfig(heartbeat=True), subscriber_detection=True)
        return session.declare_subscriber(f"{prefix}/*/status", on_sample)

    subscribers = {kind: subscribe(kind) for kind in KINDS}
    tokens: set[int] = set()
    token = session.liveliness().declare_token(f"{prefix}/{me}/alive")
    alive = session.liveliness().declare_subscriber(
        f"{prefix}/*/alive", lambda sample: tokens.add(int(str(sample.key_expr).split("/")[1]))
        if sample.kind == zenoh.SampleKind.PUT else None, history=True)
    best_effort = session.declare_publisher(f"{prefix}/{me}/plan", reliability=zenoh.Reliability.BEST_EFFORT,
                                            express=True, congestion_control=zenoh.CongestionControl.DROP)
    reliable = zext.declare_advanced_publisher(
        session, f"{prefix}/{me}/plan", cache=zext.CacheConfig(max_samples=1), publisher_detection=True,
        sample_miss_detection=zext.MissDetectionConfig(heartbeat=0.5), reliability=zenoh.Reliability.RELIABLE,
        congestion_control=zenoh.CongestionControl.DROP)
    status = session.declare_publisher(f"{prefix}/{me}/status", reliability=zenoh.Reliability.BEST_EFFORT)
    payload, resubscribed, last_resubscribed = b"p" * 700, 0, {}
    others = {j: True for j in range(1, peers + 1) if j != me}  # as if every token had come
    frequent = FREQUENT if watch == "behind" else ()
    while (now := time.monotonic()) - started < seconds:
        best_effort.put(payload)
        reliable.put(payload)
        status.put(b"s")
        if watch:
            for kind in silent_kinds(dict(heard), others, KINDS, now, started, dict(first), frequent):
                if now - last_resubscribed.get(kind, -1e9) >= RESUBSCRIBE_EVERY_S:
                    last_resubscribed[kind] = now
                    subscribers[kind].undeclare()
                    subscribers[kind] = subscribe(kind)
                    resubscribed += 1
        time.sleep(0.1)
    end = time.monotonic()
    for j in others:  # a peer not heard lately: silent until the end
        note_silence(j, end)
    lost = [(j, kind) for j in range(1, peers + 1) if j != me for kind in KINDS if heard.get((j, kind), 0.0) < end - 1.0]
    missed = [j for j in range(1, peers + 1) if j != me and j not in tokens]
    alive.undeclare()
    token.undeclare()
    session.close()
    out.put((me, lost, resubscribed, missed, max(silence.values(), default=0.0)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--starts", type=int, default=50)
    parser.add_argument("--peers", type=int, default=4)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--dial", choices=("all", "lower"), default="all")
    parser.add_argument("--watch", choices=("silent", "behind"), default=None,
                        help="subscribe again to a kind gone silent: fleet.bus.session's rule ('behind'), or without "
                             "its plans-behind part ('silent')")
    parser.add_argument("--tcp-only", action="store_true", help="no UDP endpoints: one TCP link per pair")
    args = parser.parse_args()
    lost_starts = missed_starts = 0
    silences: list[float] = []
    for start in range(args.starts):
        endpoints = {i: (f"tcp/127.0.0.1:{free_port()}",) + (
            () if args.tcp_only else (f"udp/127.0.0.1:{free_port(socket.SOCK_DGRAM)}?rel=0",))
            for i in range(1, args.peers + 1)}
        out = mp.Queue()
        processes = []
        for i in range(1, args.peers + 1):
            dial = [e for j, pair in endpoints.items() if args.dial == "all" or j < i for e in pair]
            process = mp.Process(target=peer, args=(i, args.peers, endpoints[i], tuple(dial), f"race{start}",
                                                    args.seconds, args.watch, out))
            process.start()
            processes.append(process)
        results = [out.get(timeout=60 + args.seconds) for _ in processes]
        for process in processes:
            process.join()
        lost = [(me, j, kind) for me, pairs, _, _, _ in results for j, kind in pairs]
        missed = [(me, j) for me, _, _, tokens, _ in results for j in tokens]
        silence = max(r[4] for r in results)
        silences.append(silence)
        lost_starts += bool(lost)
        missed_starts += bool(missed)
        print(f"start {start}: {'LOST ' + str(lost) if lost else 'ok'}, resubscribed {sum(r[2] for r in results)}, "
              f"plan silence {silence:.2f} s{', tokens MISSED (seer, owner) ' + str(missed) if missed else ''}",
              flush=True)
    long = sum(s > 0.5 for s in silences)
    print(f"{lost_starts} of {args.starts} starts lost a subscription, {missed_starts} missed a liveliness token "
          f"(dial {args.dial}, watch {args.watch or 'off'}, {'TCP only' if args.tcp_only else 'TCP and UDP'}); "
          f"plans silent for over 0.5 s after the first second in {long} starts, longest {max(silences):.2f} s")


if __name__ == "__main__":
    main()
