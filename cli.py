"""The ``trustfg`` command: one entry point, one subcommand per process kind.

Each subcommand lives in its own module with a ``main(argv) -> int``; this module only
dispatches (importing the one it runs), so ``trustfg car`` does not import the
dashboard's web stack and the like. It sits above every layer. ``trustfg stop`` sets up
logging itself, after its first E_STOPs are out (fleet.operator.estop_first): this module imports
nothing before it.
"""

from __future__ import annotations

import importlib
import os
import sys

BLAS_THREADS = "1"
"""OpenBLAS threads per process (numpy and scipy each carry their own OpenBLAS, each
starting one thread per core). A fleet's processes do small-matrix work, many of them
per computer (a whole fleet on a laptop, a car computer of 2-4 cores): one BLAS thread
each, so none spins up worker threads that compete with the others' control loops.
Set here, before any subcommand imports numpy; an OPENBLAS_NUM_THREADS set by the user
is kept."""

COMMANDS = {
    "sim": ("trustfg.fleet.launch.launcher", "the main job: a whole fleet as OS processes with mocap-sim"),
    "car": ("trustfg.fleet.car.process", "one car's process: agent and bridge (lab or simulation)"),
    "mocap-sim": ("trustfg.mocap_sim.sim", "simulated cars and OptiTrack (NatNet) for a fleet config"),
    "faults": ("trustfg.fleet.faultlab.matrix", "the fault matrix: a fleet in network namespaces under each fault (root)"),
    "go": ("trustfg.fleet.operator.go", "the operator's session: start a trial, watch it, stop it (keys)"),
    "stop": ("trustfg.fleet.operator.estop", "emergency stop (or release, or abort) of the fleet or some cars"),
    "check": ("trustfg.fleet.operator.check", "bring-up check, motors held: poses, links, bus, clocks, what is missing"),
    "calibrate": ("trustfg.fleet.operator.calibrate", "drive one car through a short pattern and measure its limits"),
    "carlink-test": ("trustfg.bridge.carlink.conformance", "probe a car's link, rule by rule of the receiver (wheels off the floor)"),
    "router": ("trustfg.fleet.bus.router", "a Zenoh router (no zenohd needed) for cars that talk through one"),
    "dashboard": ("trustfg.dashboard.server", "the live web page of a fleet, or a recorded run replayed"),
    "record": ("trustfg.fleet.recording.mcap_file", "record a live fleet to an MCAP file"),
    "foxglove": ("trustfg.dashboard.foxglove_live", "serve the live fleet to Foxglove (WebSocket protocol)"),
    "report": ("trustfg.dashboard.report", "figures and an HTML report from a recorded run"),
    "keys": ("trustfg.fleet.operator.keys", "a fleet's car-link keys and TLS certificates, and where each goes"),
    "secure-config": ("trustfg.fleet.bus.security", "Zenoh mutual-TLS and access-control config for one fleet member"),
    "experiment": ("trustfg.fleet.experiments.paper", "run the paper's experiments (and the scenario bank) in-process"),
    "scenario": ("trustfg.fleet.sim.scene_gen", "generate a scene from a seed, or check a scene's starts and goals"),
    "config": ("trustfg.agent.config.command_line", "the configuration: every key's reference, or a run's effective settings"),
}


def setup_logging() -> None:
    import logging

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: trustfg COMMAND [options]\n\ncommands:")
        for name, (_, text) in COMMANDS.items():
            print(f"  {name:<13} {text}")
        print("\n'trustfg COMMAND --help' tells more; 'trustfg --version' prints the version.")
        return 0 if argv else 2
    if argv[0] in ("-V", "--version"):
        from . import __version__

        print(f"trustfg {__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"trustfg: unknown command {name!r} (try 'trustfg --help')", file=sys.stderr)
        return 2
    os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)
    module = importlib.import_module(COMMANDS[name][0])
    try:
        if name == "stop":  # the e-stop: logging once its first datagrams are out
            return int(module.main(rest, ready=setup_logging) or 0)
        setup_logging()
        return int(module.main(rest) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
