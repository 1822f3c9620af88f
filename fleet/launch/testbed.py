"""A loopback fleet whose operator is the caller: for tests and benchmarks of the operator's
protocol (trials, e-stops, the deadman, restarts).

:class:`LoopbackFleet` wires a scenario as ``trustfg sim`` does (fleet.launch.launcher), starts
``trustfg mocap-sim`` (with a command log and its run-time control port) and one
``trustfg car`` process per car, each in its own process group, and joins the bus as
the operator (fleet.operator.session.OperatorSession), whose heartbeat and bus a background
thread keeps going (``heartbeat`` switches the heartbeat off and on). Unlike
``trustfg sim`` it sends no start: the caller does. Everything stops on exit.

What the cars apply comes from mocap-sim's command log (every change of a car's command
between zero and non-zero, on the fleet clock, at physics resolution):
:meth:`CommandLog.held_since` says since when each car has applied zero for good.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

from ...agent import messages
from ...agent.config import Scenario
from ...agent.scenario_files import dump_scenario
from ..bus.session import FleetBus
from ..operator.session import OperatorSession
from .launcher import free_port, loopback_fleet, with_deadman
from .link_keys import with_link_keys
from .processes import Processes, wait_ready


class LoopbackFleet:
    def __init__(self, scenario: Scenario, out: Path, *, deadman_s: float | None = None,
                 mocap_args: tuple[str, ...] = (), cars_first: tuple[int, ...] | None = None):
        self.fleet = with_link_keys(with_deadman(loopback_fleet(scenario, None, None, 0.0), deadman_s), out / "keys")
        self.out = out
        self.config = out / "fleet.toml"
        self.command_log = out / "commands.csv"
        self.log = CommandLog(self.command_log)
        self.control_port = free_port(socket.SOCK_DGRAM)
        self.mocap_args = mocap_args
        self.cars_first = cars_first
        """Start only these car processes (None: every car); the rest with start_cars()."""
        self.processes = Processes()
        self.heartbeat = threading.Event()
        self.heartbeat.set()
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self.bus: FleetBus | None = None
        self.session: OperatorSession | None = None
        self.inbox = messages.Inbox()

    # --- lifecycle --------------------------------------------------------------------------

    def __enter__(self) -> "LoopbackFleet":
        self.out.mkdir(parents=True, exist_ok=True)
        self.config.write_text(dump_scenario(self.fleet))
        try:
            if self.cars_first is None:
                self.start_mocap()
            self.start_cars(self.cars_first)
            self.bus = FleetBus(self.fleet.bus, self.fleet.fleet, None,
                                listen=(f"tcp/127.0.0.1:{free_port()}",), kinds=("status",), operator_kinds=())
            self.bus.open()
            self.session = OperatorSession(self.fleet, self.bus)
            self._thread = threading.Thread(target=self._keep_up, name="testbed-operator", daemon=True)
            self._thread.start()
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._halt.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.session is not None:
            self.session.close()
        if self.bus is not None:
            self.bus.close()
        self.resume_cars()
        self.processes.stop()

    def start_mocap(self) -> None:
        mocap = self.processes.start("mocap-sim", [
            "mocap-sim", "--config", str(self.config), "--command-log", str(self.command_log),
            "--control-port", str(self.control_port), *self.mocap_args], self.out / "mocap_sim.log",
            stdout=subprocess.PIPE)
        wait_ready(mocap, threading.Event())

    def start_cars(self, ids: tuple[int, ...] | None = None) -> None:
        for car in self.fleet.cars:
            if ids is None or car.id in ids:
                self.start_car(car.id)

    def start_car(self, car_id: int) -> None:
        self.processes.start(f"car {car_id}", ["car", "--id", str(car_id), "--config", str(self.config),
                                               "--stats", str(self.out / f"car_{car_id}.json")],
                             self.out / f"car_{car_id}.log")

    def kill_car(self, car_id: int) -> None:
        self.processes.kill(f"car {car_id}")

    def pause_cars(self) -> None:
        """SIGSTOP every car process: they send nothing, hear nothing."""
        for name, process in self.processes.children.items():
            if name.startswith("car") and process.poll() is None:
                os.killpg(process.pid, signal.SIGSTOP)

    def resume_cars(self) -> None:
        for name, process in self.processes.children.items():
            if name.startswith("car") and process.poll() is None:
                os.killpg(process.pid, signal.SIGCONT)

    def control(self, command: dict) -> None:
        """A run-time command to mocap-sim (``{"reset": True}`` carries every car back)."""
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(json.dumps(command).encode(), ("127.0.0.1", self.control_port))

    def _keep_up(self) -> None:
        while not self._halt.is_set():
            if self.heartbeat.is_set():
                self.session.step()
            elif self.session.stopper is not None:
                self.session.stopper.step(time.time())
            for received in self.bus.drain():
                message = self.inbox.accept(received.payload, key_sender=received.sender)
                if message is not None:
                    self.session.heard(message, received.at)
            self.bus.wait(0.01)

    # --- what the cars do ---------------------------------------------------------------------

    @property
    def ids(self) -> list[int]:
        return [c.id for c in self.fleet.cars]

    def states(self) -> dict[int, str]:
        return {car: seen.state for car, seen in self.session.cars.items()}

    def wait_states(self, wanted: set[str], cars: list[int] | None = None, timeout_s: float = 10.0) -> bool:
        deadline = time.monotonic() + timeout_s
        cars = self.ids if cars is None else cars
        while time.monotonic() < deadline:
            if all(self.session.cars[c].state in wanted for c in cars):
                return True
            time.sleep(0.02)
        return False

    def commands(self) -> list[tuple[float, int, float, float]]:
        return self.log.commands()

    def moving(self, at: float | None = None) -> set[int]:
        return self.log.moving(at)

    def held_since(self, since: float, cars) -> dict[int, float | None]:
        return self.log.held_since(since, cars)

    def moved_after(self, since: float) -> set[int]:
        return self.log.moved_after(since)

class CommandLog:
    """mocap-sim's command log (``--command-log``): every change of a car's applied command
    between zero and non-zero, (t, car, v, omega) on the fleet clock."""

    def __init__(self, path: Path):
        self.path = path

    def commands(self) -> list[tuple[float, int, float, float]]:
        rows = []
        try:
            with open(self.path, newline="") as f:
                for r in csv.DictReader(f):
                    try:
                        rows.append((float(r["t"]), int(r["car_id"]), float(r["v_cmd"]), float(r["omega_cmd"])))
                    except (TypeError, ValueError):  # a line being written
                        continue
        except OSError:
            pass
        return rows

    def moving(self, at: float | None = None) -> set[int]:
        """Cars applying a non-zero command at ``at`` (default: now), per the command log."""
        at = time.time() if at is None else at
        last: dict[int, bool] = {}
        for t, car, v, omega in self.commands():
            if t <= at:
                last[car] = bool(v or omega)
        return {car for car, on in last.items() if on}

    def held_since(self, since: float, cars: set[int] | list[int]) -> dict[int, float | None]:
        """For each car, since when it has applied zero for good, counted from ``since``:
        the last change to zero after ``since`` (``since`` itself if it was at zero then
        and never moved after); None while it still moves."""
        state = {car: (False, since) for car in cars}  # (moving, since when)
        for t, car, v, omega in self.commands():
            if car in state and (t <= since or (v or omega) != state[car][0]):
                state[car] = (bool(v or omega), max(t, since))
        return {car: None if on else at for car, (on, at) in state.items()}

    def moved_after(self, since: float) -> set[int]:
        """Cars that applied a non-zero command at any moment after ``since``."""
        return {car for t, car, v, omega in self.commands() if t > since and (v or omega)}


def links_to_sinks(scenario: Scenario, folder: Path) -> tuple[Path, list[socket.socket]]:
    """A config file (``folder/fleet.toml``) of ``scenario`` whose cars' links are UDP
    sockets bound here, one per car in order, with fresh keys (fleet.launch.link_keys): what the
    operator's tools send straight to the cars arrives there. The caller closes the sockets."""
    sinks = []
    try:
        for _ in scenario.cars:
            sinks.append(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
            sinks[-1].bind(("127.0.0.1", 0))
    except OSError:
        for sink in sinks:
            sink.close()
        raise
    cars = tuple(dataclasses.replace(car, link=f"udp://127.0.0.1:{sink.getsockname()[1]}")
                 for car, sink in zip(scenario.cars, sinks))
    config = folder / "fleet.toml"
    config.write_text(dump_scenario(with_link_keys(dataclasses.replace(scenario, cars=cars), folder / "keys")))
    return config, sinks
