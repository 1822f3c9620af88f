"""Plan propagation over Zenoh on loopback, beside raw Zenoh ping-pong, in one run.

    python benchmarks/bench_bus.py [--count 2000]

Two OS processes on 127.0.0.1 (explicit TCP endpoints, multicast scouting off):

* raw ping-pong: the sender puts the encoded bytes of a 41-state plan on a raw Zenoh
  key; the echo process puts them straight back from its callback. Round trip and
  one-way (time.monotonic is one clock for every process on a machine).
* plan propagation: the sender publishes through trustfg.fleet.bus.session.FleetBus (the cached advanced
  publisher cars use); the peer drains its FleetBus queue, decodes and validates the
  message (agent.messages.Inbox) and notes the time. One way, publish to decoded.

Medians and p99s in ms; the acceptance is plan p99 <= 5 ms and <= 1.5x the raw one-way.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import statistics
import time

import numpy as np
import zenoh

from trustfg.agent import messages
from trustfg.agent.config import BusConfig
from trustfg.agent.gp import Plan
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.bus.zenoh_setup import zenoh_config
from trustfg.fleet.launch.ports import free_port

FLEET = "bench"



def plan_bytes(seq: int) -> bytes:
    rng = np.random.default_rng(seq)
    plan = Plan(time.time(), 0.3, rng.normal(size=(41, 2)), rng.normal(size=(41, 2)))
    return messages.encode(messages.PlanMessage(1, seq, time.time(), plan, (0.4, 2.15)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=2000)
    args = parser.parse_args()
    a, b = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    ctx = mp.get_context("spawn")
    ready, results = ctx.Event(), ctx.Queue()
    echo = ctx.Process(target=peer_process, args=(b, a, ready, results, args.count))
    with FleetBus(BusConfig(listen=(a,), connect=(b,)), FLEET, 1) as bus:
        session = zenoh.open(zenoh_config(BusConfig(listen=(f"tcp/127.0.0.1:{free_port()}",), connect=(b,))))
        echo.start()
        ready.wait(30)
        time.sleep(1.0)  # let both sessions discover each other's subscriptions
        rtts = []
        got = mp.Event()
        got_at = []
        session.declare_subscriber("bench/pong", lambda s: (got_at.append(time.monotonic()), got.set()))
        ping = session.declare_publisher("bench/ping", express=True)
        payload = plan_bytes(0)
        for _ in range(args.count):
            got.clear()
            sent = time.monotonic()
            ping.put(payload, attachment=sent.hex())
            if got.wait(1.0):
                rtts.append(got_at[-1] - sent)
            time.sleep(0.002)
        for seq in range(1, args.count + 1):
            bus.publish("plan", stamped_plan(seq))
            time.sleep(0.002)
        result = json.loads(results.get(timeout=120))
        echo.join(10)
        session.close()
    report("raw ping-pong round trip", rtts)
    report("raw one-way (ping)", result["raw_one_way"])
    report("plan publish -> decoded", result["plan"])
    raw_p99 = float(np.percentile(result["raw_one_way"], 99)) * 1e3
    plan_p99 = float(np.percentile(result["plan"], 99)) * 1e3
    print(f"plan p99 {plan_p99:.3f} ms: {'<=' if plan_p99 <= 5 else '>'} 5 ms; "
          f"{plan_p99 / raw_p99:.2f}x raw one-way p99")


def stamped_plan(seq: int) -> bytes:
    """A plan whose stamp is time.monotonic() at publication, so the peer can time it."""
    rng = np.random.default_rng(seq)
    plan = Plan(0.0, 0.3, rng.normal(size=(41, 2)), rng.normal(size=(41, 2)))
    return messages.encode(messages.PlanMessage(1, seq, time.monotonic(), plan, (0.4, 2.15)))


def peer_process(listen: str, connect: str, ready, results, count: int) -> None:
    """The peer: echoes raw pings; times plans from publication to decoded."""
    session = zenoh.open(zenoh_config(BusConfig(listen=(f"tcp/127.0.0.1:{free_port()}",), connect=(connect,))))
    pong = session.declare_publisher("bench/pong", express=True)
    raw_one_way = []

    def on_ping(sample):
        raw_one_way.append(time.monotonic() - float.fromhex(sample.attachment.to_string()))
        pong.put(sample.payload)

    session.declare_subscriber("bench/ping", on_ping)
    delays = []
    inbox = messages.Inbox()
    with FleetBus(BusConfig(listen=(listen,), connect=(connect,)), FLEET, 2) as bus:
        ready.set()
        deadline = time.monotonic() + 300
        while len(delays) < count and time.monotonic() < deadline:
            bus.wait(0.5)
            for received in bus.drain():
                if received.kind != "plan":
                    continue
                message = inbox.accept(received.payload, key_sender=received.sender)
                if message is not None:
                    delays.append(time.monotonic() - message.stamp)
    session.close()
    results.put(json.dumps({"raw_one_way": raw_one_way, "plan": delays}))


def report(label: str, samples: list[float]) -> None:
    ms = np.array(samples) * 1e3
    print(f"{label:28s} n={len(ms):5d}  median {statistics.median(ms):7.3f} ms  p99 {np.percentile(ms, 99):7.3f} ms")


if __name__ == "__main__":
    main()
