"""``trustfg mocap-sim --config FILE``: the lab's hardware, simulated.

:class:`MocapSim` gives every car of the config a simulated car (agent.vehicle) behind
a :class:`~trustfg.bridge.carlink.CommandReceiver` on the car's ``link`` address -- the very
receiving rules firmware runs, watchdog and e-stop included -- and streams every car's pose
through a NatNet server (mocap_sim.natnet_server) as Motive would. Physics runs on absolute
deadlines; ground truth and a log of the cars' commands go to CSV files; a control port
takes faults at run time. What the command offers its user is :data:`DESCRIPTION` (its
--help); the design is in docs/design/links.md, "mocap-sim: the hardware, simulated".
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import logging
import math
import socket
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..agent.config import ConfigError, Scenario, VehicleConfig, parse_udp_address
from ..agent.scenario_files import load_scenario, load_vehicle
from ..agent.vehicle import VehicleState, step
from ..bridge import natnet
from ..bridge.carlink import CommandReceiver, link_key
from ..bridge.natnet_client import NatNetConnectionError
from ..fleet.car.ticker import ticks
from ..fleet.program import command_parser, configured, stop_on_signals
from .natnet_server import NatNetServer, NatNetServerOptions, Occlusion
from .relay import RelayOptions, check_relay, relayed, served_version

log = logging.getLogger(__name__)

BODY_HEIGHT_M = 0.05

DESCRIPTION = """\
``trustfg mocap-sim --config FILE``: the lab's hardware, simulated.

For every car of the config: a simulated car -- a unicycle, or a kinematic bicycle where
its [vehicle] says ``steering = "car"`` -- that takes the same UDP command datagrams as a
real car on its ``link`` address, through the very receiving rules real
firmware runs (the MAC with the car's key -- or the CRC of version 1 where a car's config
asks for it --, car id, sessions and sequence order, 250 ms watchdog, e-stop). A NatNet
server streams every car's pose as Motive would, at the config's NatNet address and ports.

Physics runs at ``--physics-hz`` on absolute deadlines. Ground truth (fleet clock,
every car's x, y, yaw, v, omega, and the command it is applying, v_cmd and omega_cmd --
zero once its watchdog, a STOP or an e-stop stops it) goes to ``--ground-truth FILE``
as CSV at the fleet's command rate (``control.command_rate_hz``); every change of a car's
command between zero and non-zero is also written, at physics resolution, to
``--command-log FILE`` (t, car_id, v_cmd, omega_cmd).

Fault knobs (all times in seconds since the simulator started):
  --drop-rate P          drop NatNet frames with probability P
  --noise M              Gaussian pose noise, standard deviation M metres
  --latency S            deliver every frame S seconds late
  --occlude ID:T0:T1     rigid body ID untracked (tracking-valid off) for T0 <= t < T1
  --cut-link ID:T0:T1    car ID hears no commands for T0 <= t < T1 (its watchdog stops it)
  --slip S               relative speed noise of the wheels (std)
  --command-delay S      every car applies a command S seconds after it takes it (the time
                         from a datagram to the wheels' motion that ``trustfg calibrate``
                         measures on a real car)
  --vehicle CAR=FILE     car CAR's body from the [vehicle] table of FILE (what ``trustfg
                         calibrate`` writes): its steering, turning radius and limits
                         instead of the config's [vehicle] (repeatable)
  --control-port P       take faults at run time as JSON datagrams on 127.0.0.1:P (or the
                         NatNet address): {"occlude": BODY, "seconds": S} hides a rigid body
                         from now for S seconds; {"cut_link": CAR, "seconds": S} makes a car
                         deaf to its commands; {"reset": true} puts every car back at its
                         start, standing (the lab's "carry them back" between trials);
                         anything else is refused and counted

Mixed fleets: cars marked ``simulated = false`` are real. With ``--relay LAB.toml``
mocap-sim binds no link for them and streams their rigid bodies, as the motion capture that
config's [natnet] names streams them, beside its simulated cars (docs/lab-guide.md,
"Bringing up the first real car").

The simulated cars answer PING datagrams as firmware must. The process prints the ports
it bound (NatNet, every car's link, the control port), then ``READY`` on stdout once the
stream runs, and stops cleanly on SIGTERM or SIGINT."""
"""The command's description (``trustfg mocap-sim --help``)."""


@dataclass(frozen=True)
class Window:
    """Something happens to ``id`` for start_s <= t < end_s (simulator time)."""

    id: int
    start_s: float
    end_s: float

    def covers(self, t: float) -> bool:
        return self.start_s <= t < self.end_s


def parse_vehicle(text: str) -> tuple[int, VehicleConfig]:
    """``CAR=FILE`` -> (car id, the [vehicle] table of FILE)."""
    car, sep, path = text.partition("=")
    if not (sep and car.strip().isdigit() and path):
        raise argparse.ArgumentTypeError(f"expected CAR=FILE, got {text!r}")
    try:
        return int(car), load_vehicle(path)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def parse_window(text: str) -> Window:
    try:
        ident, start, end = text.split(":")
        window = Window(int(ident), float(start), float(end))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected ID:START:END, got {text!r}") from None
    if not (math.isfinite(window.start_s) and math.isfinite(window.end_s) and window.end_s > window.start_s):
        raise argparse.ArgumentTypeError(f"need finite START < END, got {text!r}")
    return window


@dataclass(frozen=True)
class MocapSimOptions:
    natnet_version: str = ""
    """NatNet version of SERVERINFO and the frames, e.g. "3.1"; empty: the upstream's when
    relaying (mocap_sim.relay.served_version), else natnet.DEFAULT_STREAM_VERSION."""
    rate_hz: float = 120.0
    physics_hz: float = 200.0
    drop_rate: float = 0.0
    noise_m: float = 0.0
    latency_s: float = 0.0
    occlusions: tuple[Window, ...] = ()
    link_cuts: tuple[Window, ...] = ()
    slip: float = 0.0
    seed: int = 0
    ground_truth: Path | None = None
    control_port: int | None = None
    command_log: Path | None = None
    relay: RelayOptions | None = None
    """Where a mixed fleet's real cars are tracked (mocap_sim.relay); None: every car is simulated."""
    command_delay_s: float = 0.0
    """A car applies a command this long after its receiver took it."""
    vehicles: tuple[tuple[int, VehicleConfig], ...] = ()
    """(car id, body) of the cars whose body is not the config's [vehicle]."""


class MocapSim:
    def __init__(self, scenario: Scenario, options: MocapSimOptions, clock=time.time):
        check_relay(scenario, options.relay)
        self.cars = tuple(car for car in scenario.cars if car.simulated)
        """The cars simulated here; a mixed fleet's real cars are relayed (mocap_sim.relay)."""
        missing = [car.id for car in self.cars if not car.link]
        if missing:
            raise ConfigError(f"cars {missing}: mocap-sim needs every simulated car's link address")
        self.scenario = scenario
        self.options = options
        self.clock = clock
        self._keys = {car.id: link_key(car) for car in self.cars}  # version 2 cars check MACs
        self.stop = threading.Event()
        self._lock = threading.Lock()
        self.states = {car.id: VehicleState(car.start[0], car.start[1], car.start_heading) for car in self.cars}
        self.commands = {car.id: (0.0, 0.0) for car in self.cars}
        """What each car applies now (the command it took ``command_delay_s`` ago)."""
        self._taken: dict[int, deque] = {car.id: deque() for car in self.cars}
        """(time taken, v, omega) of each car's commands not yet applied."""
        unknown = sorted(set(dict(options.vehicles)) - {car.id for car in self.cars})
        if unknown:
            raise ConfigError(f"--vehicle: no simulated car {unknown[0]} in the config")
        self.vehicles = {car.id: dict(options.vehicles).get(car.id, scenario.vehicle) for car in self.cars}
        self._bodies = {car.id: car.body_id for car in self.cars}
        self._rng = np.random.default_rng([options.seed, 1])
        self._t0 = time.monotonic()
        self.hidden_until: dict[int, float] = {}
        self.deaf_until: dict[int, float] = {}
        self.control_counts = {"accepted": 0, "refused": 0}

    def bodies(self, t: float):
        """The NatNet server's pose source: every car, in Motive coordinates."""
        up = self.scenario.natnet.up_axis
        with self._lock:
            states = dict(self.states)
        now = time.monotonic()
        for car_id, state in states.items():
            position, orientation = natnet.from_ground_plane(state.x, state.y, state.yaw, BODY_HEIGHT_M, up)
            body = self._bodies[car_id]
            yield body, f"car{car_id}", position, orientation, now >= self.hidden_until.get(body, 0.0)

    def server_options(self, upstream: natnet.Version | None = None) -> NatNetServerOptions:
        """The NatNet server's options; ``upstream``: the relayed stream's NatNet version."""
        n, o = self.scenario.natnet, self.options
        if o.natnet_version:
            version = natnet.Version.parse(o.natnet_version)
        else:
            version = served_version(upstream) if upstream is not None else natnet.DEFAULT_VERSION
        return NatNetServerOptions(
            natnet_version=version, rate_hz=o.rate_hz,
            address=n.server, command_port=n.command_port, multicast=n.mode == "multicast",
            multicast_group=n.multicast_group, data_port=n.data_port, drop_rate=o.drop_rate,
            noise_std_m=o.noise_m, latency_s=o.latency_s, seed=o.seed,
            occlusions=tuple(Occlusion(w.id, w.start_s, w.end_s) for w in o.occlusions),
        )

    def run(self, ready=lambda: print("READY", flush=True)) -> int:
        receivers = {}
        try:
            for car in self.cars:
                host, port = parse_udp_address(car.link, f"cars[id={car.id}].link")
                receivers[car.id] = CommandReceiver(car.id, (host, port), key=self._keys[car.id])
                receivers[car.id].start()
            if self.options.control_port is not None:
                threading.Thread(target=self._control, name="mocap-control", daemon=True).start()
            with relayed(self.scenario, self.options.relay, self.bodies) as (source, upstream), \
                    NatNetServer(self.server_options(upstream), source) as server, \
                    self._ground_truth() as writer, _CommandLog(self.options.command_log) as command_log:
                log.info("mocap-sim: %d cars, NatNet %s %s on %s:%d", len(receivers), server.options.natnet_version,
                         self.scenario.natnet.mode, *server.command_address)
                links = " ".join(f"{car}=udp://{r.address[0]}:{r.address[1]}" for car, r in receivers.items())
                control = f", control port {self.options.control_port}" if self.options.control_port else ""
                if self.options.relay is not None:
                    up = self.options.relay.upstream
                    control += (f", relaying cars {[c.id for c in self.scenario.cars if not c.simulated]} "
                                f"from {up.server}:{up.command_port}")
                print(f"mocap-sim: NatNet on {server.command_address[0]}:{server.command_address[1]}, "
                      f"car links {links}{control}", flush=True)
                ready()
                self._physics(receivers, writer, command_log)
        finally:
            for receiver in receivers.values():
                receiver.close()
        return 0

    def _control(self) -> None:
        """Run-time faults from JSON datagrams (see :data:`DESCRIPTION`, ``--control-port``)."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind((self.scenario.natnet.server, self.options.control_port))
        sock.settimeout(0.2)
        with sock:
            while not self.stop.is_set():
                try:
                    data, _ = sock.recvfrom(2048)
                except TimeoutError:
                    continue
                try:
                    command = json.loads(data)
                    if isinstance(command, dict) and command.get("reset") is True:
                        self.reset()
                        self.control_counts["accepted"] += 1
                        continue
                    seconds = float(command["seconds"])
                    if not (isinstance(command, dict) and 0 < seconds < 3600):
                        raise ValueError("seconds out of range")
                    until = time.monotonic() + seconds
                    if "occlude" in command:
                        self.hidden_until[int(command["occlude"])] = until
                    elif "cut_link" in command and int(command["cut_link"]) in self.states:
                        self.deaf_until[int(command["cut_link"])] = until
                    else:
                        raise ValueError("unknown command")
                    self.control_counts["accepted"] += 1
                    log.info("mocap-sim: fault %s", command)
                except (ValueError, KeyError, TypeError) as exc:
                    self.control_counts["refused"] += 1
                    log.warning("mocap-sim: refused control datagram: %s", exc)

    def reset(self) -> None:
        """Every car back at its start, standing."""
        with self._lock:
            self.states = {car.id: VehicleState(car.start[0], car.start[1], car.start_heading)
                           for car in self.cars}
        log.info("mocap-sim: every car back at its start")

    def _ground_truth(self) -> "_CsvWriter":
        return _CsvWriter(self.options.ground_truth)

    def _physics(self, receivers: dict[int, CommandReceiver], writer: "_CsvWriter",
                 command_log: "_CommandLog") -> None:
        period = 1.0 / self.options.physics_hz
        truth_period = 1.0 / self.scenario.control.command_rate_hz
        next_truth = time.monotonic()
        delay = self.options.command_delay_s
        for _, now in ticks(period, self.stop, max_lag_periods=5):
            t_sim = now - self._t0
            with self._lock:
                for car_id, state in self.states.items():
                    receiver = receivers[car_id]
                    cut = (any(w.id == car_id and w.covers(t_sim) for w in self.options.link_cuts)
                           or now < self.deaf_until.get(car_id, 0.0))
                    if cut != receiver.deaf.is_set():  # the car hears nothing while its link is cut
                        receiver.deaf.set() if cut else receiver.deaf.clear()
                    taken = self._taken[car_id]
                    taken.append((now, *receiver.active_command(now)))
                    v, omega = self.commands[car_id]
                    while taken and taken[0][0] <= now - delay:  # the wheels follow a command delay late
                        _, v, omega = taken.popleft()
                    if (v == 0.0 and omega == 0.0) != (self.commands[car_id] == (0.0, 0.0)):
                        command_log.write(self.clock(), car_id, v, omega)
                    self.commands[car_id] = (v, omega)
                    self.states[car_id] = step(state, v, omega, period, self.vehicles[car_id], self._rng,
                                               self.options.slip)
                states = dict(self.states)
                commands = dict(self.commands)
            if now >= next_truth:
                next_truth += truth_period
                writer.write(self.clock(), states, commands)


class _CommandLog:
    def __init__(self, path: Path | None):
        self._file = open(path, "w", buffering=1) if path is not None else None
        if self._file:
            self._file.write("t,car_id,v_cmd,omega_cmd\n")

    def __enter__(self) -> "_CommandLog":
        return self

    def __exit__(self, *exc) -> None:
        if self._file:
            self._file.close()

    def write(self, t: float, car_id: int, v: float, omega: float) -> None:
        if self._file:
            self._file.write(f"{t:.4f},{car_id},{v:.4f},{omega:.4f}\n")


class _CsvWriter:
    def __init__(self, path: Path | None):
        self._file = open(path, "w", newline="", buffering=1) if path is not None else None
        self._csv = csv.writer(self._file) if self._file else None
        if self._csv:
            self._csv.writerow(["t", "car_id", "x", "y", "yaw", "v", "omega", "v_cmd", "omega_cmd"])

    def __enter__(self) -> "_CsvWriter":
        return self

    def __exit__(self, *exc) -> None:
        if self._file:
            self._file.close()

    def write(self, t: float, states: dict[int, VehicleState], commands: dict[int, tuple[float, float]]) -> None:
        if not self._csv:
            return
        for car_id, s in states.items():
            v_cmd, omega_cmd = commands[car_id]
            self._csv.writerow([f"{t:.4f}", car_id, f"{s.x:.5f}", f"{s.y:.5f}", f"{s.yaw:.5f}",
                                f"{s.v:.4f}", f"{s.omega:.4f}", f"{v_cmd:.4f}", f"{omega_cmd:.4f}"])


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg mocap-sim", DESCRIPTION, whole=True,
                            epilog="Times of --occlude and --cut-link are seconds since the simulator started.")
    parser.add_argument("--config", required=True, type=Path, help="fleet config TOML (cars need link addresses)")
    parser.add_argument("--natnet-version", choices=natnet.STREAM_VERSIONS, default="",
                        help="NatNet version of SERVERINFO and the frames (default: the upstream's with --relay, "
                             f"else {natnet.DEFAULT_STREAM_VERSION})")
    parser.add_argument("--rate", type=float, default=120.0, help="NatNet frame rate, Hz (default 120)")
    parser.add_argument("--physics-hz", type=float, default=200.0, help="physics rate, Hz (default 200)")
    parser.add_argument("--drop-rate", type=float, default=0.0, help="probability of dropping a frame (0..1)")
    parser.add_argument("--noise", type=float, default=0.0, help="pose noise standard deviation, m")
    parser.add_argument("--latency", type=float, default=0.0, help="frame latency, s")
    parser.add_argument("--occlude", type=parse_window, action="append", default=[],
                        metavar="BODY:START:END", help="rigid body untracked in this window (repeatable)")
    parser.add_argument("--cut-link", type=parse_window, action="append", default=[],
                        metavar="CAR:START:END", help="car hears no commands in this window (repeatable)")
    parser.add_argument("--slip", type=float, default=0.0, help="relative wheel-speed noise (std)")
    parser.add_argument("--command-delay", type=float, default=0.0, metavar="S",
                        help="every car applies a command S seconds after it takes it (default 0)")
    parser.add_argument("--vehicle", type=parse_vehicle, action="append", default=[], metavar="CAR=FILE",
                        help="car CAR's body from FILE's [vehicle] table instead of the config's (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="seed of drops, noise and slip")
    parser.add_argument("--ground-truth", type=Path, default=None, help="write ground truth CSV here")
    parser.add_argument("--command-log", type=Path, default=None,
                        help="write every change of a car's command between zero and non-zero here (CSV)")
    parser.add_argument("--control-port", type=int, default=None,
                        help="UDP port for run-time faults (JSON; see the description above)")
    parser.add_argument("--relay", type=Path, default=None, metavar="LAB.toml",
                        help="relay the real cars (simulated = false) from the motion capture this config's "
                             "[natnet] names")
    parser.add_argument("--relay-stale", type=float, default=RelayOptions.stale_s, metavar="S",
                        help="serve a real car untracked once its newest upstream pose is this old, s "
                             "(default %(default)s)")
    args = parser.parse_args(argv)
    if not 0.0 <= args.drop_rate <= 1.0:
        parser.error("--drop-rate must be within [0, 1]")
    for name in ("rate", "physics_hz"):
        if not getattr(args, name) > 0:
            parser.error(f"--{name.replace('_', '-')} must be > 0")
    for name in ("noise", "latency", "slip", "command_delay"):
        if not getattr(args, name) >= 0:
            parser.error(f"--{name.replace('_', '-')} must be >= 0")
    if not args.relay_stale > 0:
        parser.error("--relay-stale must be > 0")
    options = MocapSimOptions(
        natnet_version=args.natnet_version, rate_hz=args.rate, physics_hz=args.physics_hz,
        drop_rate=args.drop_rate, noise_m=args.noise, latency_s=args.latency,
        occlusions=tuple(args.occlude), link_cuts=tuple(args.cut_link), slip=args.slip,
        seed=args.seed, ground_truth=args.ground_truth, control_port=args.control_port,
        command_log=args.command_log, command_delay_s=args.command_delay, vehicles=tuple(args.vehicle))

    def build() -> MocapSim:
        relay = None if args.relay is None else RelayOptions(load_scenario(args.relay).natnet, args.relay_stale)
        return MocapSim(load_scenario(args.config), dataclasses.replace(options, relay=relay))

    sim = configured("trustfg mocap-sim", build)
    stop_on_signals(sim.stop)
    try:
        return configured("trustfg mocap-sim", sim.run)  # the relay's upstream is checked as it starts
    except NatNetConnectionError as exc:
        print(f"trustfg mocap-sim: --relay: {exc}", file=sys.stderr)
        return 1
