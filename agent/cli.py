"""The ``trustfg`` command: one entry point, one subcommand per process kind.

Each subcommand lives in its own module with a ``main(argv) -> int``; this module only
dispatches, so ``trustfg car`` does not import the dashboard's web stack and the like.
"""

from __future__ import annotations

import importlib
import logging
import signal
import sys
import threading

COMMANDS = {
    "sim": ("agent.launch", "the main job: a whole fleet as OS processes with mocap-sim"),
    "car": ("agent.car_process", "one car's process: agent and bridge (lab or simulation)"),
    "mocap-sim": ("mocap_sim.sim", "simulated cars and OptiTrack (NatNet) for a fleet config"),
    "faults": ("mocap_sim.faults", "the fault matrix: a fleet in network namespaces under each fault (root)"),
    "go": ("agent.go", "the operator's start signal for a fleet in the lab"),
    "dashboard": ("dashboard.server", "the live web page of a fleet, or a recorded run replayed"),
    "record": ("dashboard.recording", "record a live fleet to an MCAP file"),
    "report": ("dashboard.report", "figures and an HTML report from a recorded run"),
    "secure-config": ("agent.security", "Zenoh mutual-TLS and access-control config for one fleet member"),
    "experiment": ("agent.experiments", "run the paper's experiments in the in-process simulation"),
}


def stop_on_signals(stop: threading.Event) -> threading.Event:
    """SIGTERM and SIGINT set ``stop`` (a process's loops end, then it cleans up)."""
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    return stop


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: trustfg COMMAND [options]\n\ncommands:")
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:<12} {text}")
        print("\n'trustfg COMMAND --help' tells more.")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"trustfg: unknown command {name!r} (try 'trustfg --help')", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    module = importlib.import_module(COMMANDS[name][0])
    try:
        return int(module.main(rest) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
