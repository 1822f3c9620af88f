"""What decoding a fleet message costs beyond msgpack itself.

    python benchmarks/bench_messages.py [--repeat 20000]

Encodes a plan message (21 support states) and a trust report (8 peers) with
agent.messages, then times, per message: msgpack's own unpacking of the bytes, our
decode (msgpack plus every check: kinds, ranges, finite numbers, array shapes) and our
encode. The difference between the first two is what validation costs a car on every
message it hears.
"""

from __future__ import annotations

import argparse
import time

import msgpack
import numpy as np

from trustfg.agent import messages
from trustfg.agent.gp import Plan
from trustfg.agent.messages import PeerTrust, PlanMessage, TrustReport


def per_call_us(function, repeat: int) -> float:
    started = time.perf_counter()
    for _ in range(repeat):
        function()
    return (time.perf_counter() - started) / repeat * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=20000, help="calls timed per figure (default: 20000)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    plan = Plan(t0=1.0, dt=0.25, positions=rng.random((21, 2)), velocities=rng.random((21, 2)))
    samples = {
        "plan, 21 states": PlanMessage(3, 17, 1.0, plan, (1.0, 2.0), deadlocks=0),
        "trust, 8 peers": TrustReport(3, 5, 1.0, {p: PeerTrust((1.0, 2.0, 3.0), (0.1, 0.2, 0.3), (0.9, 0.8, 0.7),
                                                              0.7, 0.3) for p in range(1, 9)}),
    }
    print(f"{'message':<16} {'bytes':>6} {'msgpack us':>11} {'decode us':>10} {'x msgpack':>10} {'encode us':>10}")
    for name, message in samples.items():
        payload = messages.encode(message)
        unpack = per_call_us(lambda: msgpack.unpackb(payload, raw=False, strict_map_key=False), args.repeat)
        decode = per_call_us(lambda: messages.decode(payload), args.repeat)
        encode = per_call_us(lambda: messages.encode(message), args.repeat)
        print(f"{name:<16} {len(payload):>6} {unpack:>11.1f} {decode:>10.1f} {decode / unpack:>10.1f} {encode:>10.1f}")


if __name__ == "__main__":
    main()
