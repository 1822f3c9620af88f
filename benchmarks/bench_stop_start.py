"""``trustfg stop``'s start-up: from spawning the process to its first E_STOP datagram.

    python benchmarks/bench_stop_start.py [--spawns 30] [--scene circle-4]

Writes a fleet config whose cars' links are UDP sockets of this benchmark (fresh keys, as
``trustfg sim`` makes them), then, ``--spawns`` times each, starts ``trustfg stop
--config FILE --path link --wait 0 --repeat 0`` as the installed console script and as
``python -m trustfg`` and times, from just before the spawn, the first datagram to arrive
at each car's socket (every car's, the slowest). No car process, no bus: the part of an
e-stop's latency that is the operator's new process (bench_estop.py measures the whole).
"""

from __future__ import annotations

import argparse
import select
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.launch.testbed import links_to_sinks


def first_datagrams(command: list[str], sinks: list[socket.socket]) -> list[float]:
    """Seconds from the spawn to the first datagram at each sink (inf: none within 5 s)."""
    for sink in sinks:
        while select.select([sink], [], [], 0.0)[0]:
            sink.recv(256)
    started = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    arrived: dict[int, float] = {}
    while len(arrived) < len(sinks) and time.perf_counter() - started < 5.0:
        ready = select.select([s for i, s in enumerate(sinks) if i not in arrived], [], [], 0.5)[0]
        now = time.perf_counter() - started
        for sink in ready:
            sink.recv(256)
            arrived[sinks.index(sink)] = now
    process.wait(30)
    return [arrived.get(i, float("inf")) for i in range(len(sinks))]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spawns", type=int, default=30, help="processes started per way of starting")
    parser.add_argument("--scene", default="circle-4", help="the fleet (its cars get this benchmark's sockets)")
    args = parser.parse_args()
    scene = load_scenario(args.scene)
    config, sinks = links_to_sinks(scene, Path(tempfile.mkdtemp(prefix="bench-stop-start-")))
    try:
        stop = ["stop", "--config", str(config), "--path", "link", "--wait", "0", "--repeat", "0"]
        ways = {"console script": [str(Path(sys.executable).parent / "trustfg")],
                "python -m trustfg": [sys.executable, "-m", "trustfg"]}
        for name, command in ways.items():
            times = [first_datagrams(command + stop, sinks) for _ in range(args.spawns)]
            first = [min(t) * 1e3 for t in times]
            every = [max(t) * 1e3 for t in times]
            print(f"{name}: first E_STOP median {statistics.median(first):.1f} ms (min {min(first):.1f}, "
                  f"max {max(first):.1f}); at every car median {statistics.median(every):.1f} ms "
                  f"(max {max(every):.1f}); {args.spawns} spawns")
    finally:
        for sink in sinks:
            sink.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
