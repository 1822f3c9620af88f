"""``trustfg calibrate --config FLEET --car N``: what one car's body can do, measured under motion capture.

The car drives a short pattern -- straight on at ``--speed`` and stop, a turn in place,
and, for a car that does not turn standing, most of a circle at full lock -- while
Motive (or mocap-sim) watches. Fits of what it did (:func:`fit_ramp`, :func:`fit_circle`)
give its top speed, acceleration, braking, turn rate or minimum turning radius, and the
delay from a command to its motion; they are printed, and the car's [vehicle] table goes
to ``--out`` as TOML (:func:`vehicle_toml`). The operator's e-stop stays live throughout:
``trustfg stop`` latches the car (seen in its PING answers) or is heard on the bus, and
Ctrl-C or SIGTERM stop the car at once. docs/lab-guide.md, "Calibrating a car".
"""

from __future__ import annotations

import dataclasses
import math
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from ...agent.config import Scenario, VehicleConfig
from ...agent.scenario_files import dump_scenario
from ...bridge import natnet
from ..program import command_parser, configured, stop_on_signals

SETTLE_S = 0.6
"""The car stands this long before the pattern and between its legs."""
BRAKE_S = 1.5
TURN_S = 1.5
TURNS_IN_PLACE_RAD = math.radians(10.0)
"""A car that turns this far while told to turn standing turns in place."""
CIRCLE_RAD = 1.5 * math.pi
"""How far round the full-lock circle goes."""
CIRCLE_SETTLE_S = 0.4
"""After the circle's command takes effect, this long before the wheels are taken to be set."""
PING_PERIOD_S = 0.2
POSE_TIMEOUT_S = 0.25
"""The pattern ends (the car stopped) when the car's pose is older than this."""


class CalibrationError(RuntimeError):
    """The pattern could not run or was stopped (the message says why)."""


@dataclass(frozen=True)
class Leg:
    name: str
    duration_s: float
    v: float
    omega: float


def straight_legs(speed: float, room_m: float) -> list[Leg]:
    """Stand, straight on at ``speed`` for about ``room_m`` (what speeding up costs, braking
    gives back), stop."""
    return [Leg("stand", SETTLE_S, 0.0, 0.0), Leg("straight", room_m / speed, speed, 0.0),
            Leg("brake", BRAKE_S, 0.0, 0.0)]


def turn_legs(turn_rate: float) -> list[Leg]:
    """Told to turn standing, then to stand."""
    return [Leg("turn", TURN_S, 0.0, turn_rate), Leg("unturn", BRAKE_S, 0.0, 0.0)]


def circle_legs(speed: float, radius_guess: float) -> list[Leg]:
    """Most of a circle at full lock (a turn rate far beyond what ``speed`` allows on
    ``radius_guess``), then stop."""
    return [Leg("circle", CIRCLE_RAD * radius_guess / speed + CIRCLE_SETTLE_S, speed, 4.0 * speed / radius_guess),
            Leg("stop", BRAKE_S, 0.0, 0.0)]


# --- the fits (pure) --------------------------------------------------------------------------


def ramp_profile(times: np.ndarray, t_go: float, t_stop: float, delay: float, rise: float, top: float,
                 fall: float) -> np.ndarray:
    """The distance (or angle) a body covers by ``times`` whose rate, ``delay`` after the
    command at t_go, rises at ``rise`` to ``top`` and, ``delay`` after the command to stop at
    t_stop, falls at ``fall`` to rest: the integral of that rate, in closed form."""
    t = np.asarray(times, float)
    start, end = t_go + delay, t_stop + delay
    reach = start + top / rise  # top reached
    # rate until the stop takes effect: min(top, rise (t - start)); covered by t (<= end)
    def before(x):
        x = np.clip(x, start, None)
        ramp = np.minimum(x, reach) - start
        return 0.5 * rise * ramp**2 + top * np.clip(x - reach, 0.0, None)

    at_end = float(min(top, rise * max(end - start, 0.0)))
    covered = before(np.minimum(t, end))
    after = np.clip(t - end, 0.0, at_end / fall)
    return covered + at_end * after - 0.5 * fall * after**2


@dataclass(frozen=True)
class Ramp:
    delay_s: float
    rise: float
    top: float
    fall: float
    reached: bool
    """Whether the rate held its top for a while (else ``top`` is a lower bound)."""
    rms: float


def fit_ramp(times: np.ndarray, covered: np.ndarray, t_go: float, t_stop: float, guess: tuple[float, float, float]
             ) -> Ramp:
    """Delay, rise, top and fall of :func:`ramp_profile` that fit ``covered`` at ``times``
    best (least squares); ``guess``: (rise, top, fall) to start from."""
    rise0, top0, fall0 = guess

    def residual(p):
        return ramp_profile(times, t_go, t_stop, *p) - covered

    fit = least_squares(residual, x0=[0.05, rise0, top0, fall0], bounds=([0.0, 0.05, 0.01, 0.05], [1.0, 50.0, 10.0, 50.0]),
                        x_scale=[0.05, rise0, top0, fall0])
    delay, rise, top, fall = (float(v) for v in fit.x)
    held = (t_stop - t_go) - top / rise
    return Ramp(delay, rise, top, fall, held > 0.25, float(np.sqrt(np.mean(fit.fun**2))))


def fit_circle(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Centre (cx, cy) and radius of the circle through the points, least squares (Kasa's
    fit: x^2 + y^2 + D x + E y + F = 0 is linear in D, E, F)."""
    a = np.column_stack([x, y, np.ones_like(x)])
    b = -(x**2 + y**2)
    (d, e, f), *_ = np.linalg.lstsq(a, b, rcond=None)
    cx, cy = -d / 2, -e / 2
    return float(cx), float(cy), float(math.sqrt(max(cx**2 + cy**2 - f, 0.0)))


@dataclass(frozen=True)
class Calibration:
    car_id: int
    steering: str
    top_speed_mps: float
    accel_mps2: float
    brake_mps2: float
    delay_s: float
    turn_rate_radps: float | None = None
    """In place: the fastest turn measured."""
    turn_accel_radps2: float | None = None
    min_turn_radius_m: float | None = None
    """Car-like: the radius of its full-lock circle."""
    top_reached: bool = True

    def vehicle(self, base: VehicleConfig) -> VehicleConfig:
        """``base`` (the config's [vehicle]) with what was measured."""
        changes = dict(steering=self.steering, max_speed_mps=round(self.top_speed_mps, 3),
                       max_accel_mps2=round(min(self.accel_mps2, self.brake_mps2), 3))
        if self.steering == "car":
            changes |= dict(min_turn_radius_m=round(self.min_turn_radius_m, 3),
                            max_turn_rate_radps=round(self.top_speed_mps / self.min_turn_radius_m, 3))
        else:
            changes |= dict(max_turn_rate_radps=round(self.turn_rate_radps, 3),
                            max_turn_accel_radps2=round(self.turn_accel_radps2, 3))
        vehicle = dataclasses.replace(base, **changes)
        vehicle.validate("vehicle")
        return vehicle

    def lines(self) -> list[str]:
        """What was measured, one line each (the command's output)."""
        out = [f"top speed          {self.top_speed_mps:.3f} m/s" + ("" if self.top_reached else
                                                                      " (not held: at least this; give more --room)"),
               f"acceleration       {self.accel_mps2:.3f} m/s^2",
               f"braking            {self.brake_mps2:.3f} m/s^2",
               f"command to motion  {1e3 * self.delay_s:.0f} ms"]
        if self.steering == "car":
            out.append(f"turns in place     no: minimum turning radius {self.min_turn_radius_m:.3f} m")
        else:
            out.append(f"turns in place     yes: at most {self.turn_rate_radps:.3f} rad/s, "
                       f"{self.turn_accel_radps2:.2f} rad/s^2")
        return out


def calibrate(car_id: int, legs: list[tuple[Leg, float]], samples: np.ndarray, base: VehicleConfig) -> Calibration:
    """What the car did on the pattern's ``legs`` ((leg, when it began), pose-time) given its
    ``samples`` (rows t, x, y, yaw on the same clock)."""
    began = {leg.name: t for leg, t in legs}
    lengths = {leg.name: leg.duration_s for leg, _ in legs}
    t, x, y, yaw = samples.T
    # Straight on: the distance along the heading it stood at, from the command to rest.
    t_go, t_stop = began["straight"], began["brake"]
    standing = t < t_go
    heading = float(np.median(yaw[standing])) if standing.any() else float(yaw[0])
    origin = np.array([np.median(x[standing]), np.median(y[standing])]) if standing.any() else np.array([x[0], y[0]])
    window = (t >= t_go - SETTLE_S / 2) & (t < t_stop + lengths["brake"])
    along = (x - origin[0]) * math.cos(heading) + (y - origin[1]) * math.sin(heading)
    speed = next(leg.v for leg, _ in legs if leg.name == "straight")
    line = fit_ramp(t[window], along[window], t_go, t_stop, (base.max_accel_mps2, speed, base.max_accel_mps2))
    # Turning standing: how far it turned, and how fast.
    t_turn, t_unturn = began["turn"], began["unturn"]
    window = (t >= t_turn - SETTLE_S / 2) & (t < t_unturn + lengths["unturn"])
    turned = np.unwrap(yaw[window])
    turned = turned - turned[0]
    rate = next(leg.omega for leg, _ in legs if leg.name == "turn")
    if float(np.max(np.abs(turned))) >= TURNS_IN_PLACE_RAD:
        spin = fit_ramp(t[window], math.copysign(1.0, rate) * turned, t_turn, t_unturn,
                        (base.max_turn_accel_radps2, abs(rate), base.max_turn_accel_radps2))
        return Calibration(car_id, "in-place", line.top, line.rise, line.fall, line.delay_s, spin.top, spin.rise,
                           top_reached=line.reached)
    # A car that does not turn standing: the circle it drives at full lock, once set.
    circle = next(leg for leg, _ in legs if leg.name == "circle")
    t_circle = began["circle"]
    steady = (t >= t_circle + line.delay_s + circle.v / line.rise + CIRCLE_SETTLE_S) & (t < began["stop"])
    if steady.sum() < 10:
        raise CalibrationError("too few poses on the circle to fit it")
    _, _, radius = fit_circle(x[steady], y[steady])
    return Calibration(car_id, "car", line.top, line.rise, line.fall, line.delay_s, min_turn_radius_m=radius,
                       top_reached=line.reached)


def vehicle_toml(calibration: Calibration, vehicle: VehicleConfig, fleet: str, when: str) -> str:
    """The [vehicle] table to paste into the fleet's config, with what was measured and how."""
    text = dump_scenario(Scenario(name="", cars=(), vehicle=vehicle))
    table = text[text.index("[vehicle]"):].split("\n\n")[0]
    header = [f"# trustfg calibrate: car {calibration.car_id} of {fleet}, {when}"]
    header += [f"#   {line}" for line in calibration.lines()]
    header.append(f"# guard.reaction_s should be at least the command-to-motion delay ({calibration.delay_s:.3f} s) "
                  "plus the pose's age; max_accel_mps2 is the smaller of speeding up and braking"
                  + ("; wheelbase_m is not measured: set it to the car's" if calibration.steering == "car" else ""))
    return "\n".join(header) + "\n" + table.strip() + "\n"


# --- driving the pattern (I/O) ----------------------------------------------------------------


class Pattern:
    """Drives the legs one after another at the command rate, stopping the car on any
    reason to; what it saw is in :attr:`samples` and :attr:`legs` (pose time: monotonic)."""

    def __init__(self, fleet: Scenario, car_id: int, stop: threading.Event, bus: bool = True,
                 room_m: float = 2.0, out=print):
        from ...bridge.carlink import CommandSender
        from ...bridge.carlink.frame import SOURCE_OPERATOR

        self.fleet, self.car = fleet, fleet.car(car_id)
        self.stop = stop
        self.room_m = room_m
        self.out = out
        self.samples: list[tuple[float, float, float, float]] = []
        self.legs: list[tuple[Leg, float]] = []
        self._lock = threading.Lock()
        self.sender = CommandSender.for_car(self.car, source=SOURCE_OPERATOR)
        self._bus = bus
        self.opened = 0.0

    def on_frame(self, frame, received_s: float) -> None:
        """NatNet's thread: the car's pose, stamped with its arrival (never blocks)."""
        for body in frame.rigid_bodies:
            if body.id == self.car.body_id and body.tracking_valid:
                x, y, yaw = natnet.to_ground_plane(body.position, body.orientation, self.fleet.natnet.up_axis)
                with self._lock:
                    self.samples.append((received_s, x, y, yaw))

    def latest(self) -> tuple[float, float, float, float] | None:
        with self._lock:
            return self.samples[-1] if self.samples else None

    def drive(self, legs: list[Leg], bus) -> None:
        """Command each leg for its duration at the command rate, a leg's first datagram the
        moment it begins; raise CalibrationError (the car stopped) when the operator stops it
        (Ctrl-C, SIGTERM, its latch, the bus), its pose is lost or it leaves its room."""
        from ...bridge.carlink.frame import Flags

        period = 1.0 / self.fleet.control.command_rate_hz
        start = self.latest()
        next_ping = 0.0
        for leg in legs:
            began = time.monotonic()
            self.legs.append((leg, began))
            k = 0
            while (now := time.monotonic()) < began + leg.duration_s:
                if self.stop.is_set():
                    raise CalibrationError("stopped (Ctrl-C or SIGTERM)")
                pose = self.latest()
                if pose is None or now - pose[0] > POSE_TIMEOUT_S:
                    raise CalibrationError(f"car {self.car.id}: no fresh pose from the motion capture")
                if math.hypot(pose[1] - start[1], pose[2] - start[2]) > self.room_m + 0.5:
                    raise CalibrationError(f"car {self.car.id}: more than --room + 0.5 m from where it started")
                self.sender.send(leg.v, leg.omega)
                if now >= next_ping:
                    next_ping = now + PING_PERIOD_S
                    self.sender.send(0.0, 0.0, Flags.PING)
                    if any(answer.e_stop_latched for answer in self.sender.answers()):
                        raise CalibrationError(f"car {self.car.id}: e-stopped (its latch is on)")
                    if bus is not None and self._stopped_on_bus(bus):
                        raise CalibrationError(f"car {self.car.id}: the operator's stop on the bus")
                k += 1
                self.stop.wait(max(0.0, began + k * period - time.monotonic()))

    def _stopped_on_bus(self, bus) -> bool:
        from ...agent import messages

        for received in bus.drain():
            try:
                message = messages.decode(received.payload)
            except messages.MessageError:
                continue
            if isinstance(message, messages.StopMessage) and message.action in ("estop", "abort") \
                    and message.names(self.car.id) and message.stamp >= self.opened:
                return True
        return False

    def run(self, speed: float, turn_rate: float) -> Calibration:
        """The whole pattern; the car stopped at the end, whatever happens."""
        from ...bridge.natnet_client import NatNetClient, client_options
        from ..bus.session import FleetBus

        self.opened = time.time()
        bus = FleetBus(self.fleet.bus, self.fleet.fleet, None, kinds=(), operator_kinds=("stop",)) \
            if self._bus else None
        try:
            if bus is not None:
                bus.open()
            with NatNetClient(client_options(self.fleet.natnet), on_frame=self.on_frame):
                deadline = time.monotonic() + 3.0
                while self.latest() is None and time.monotonic() < deadline and not self.stop.wait(0.05):
                    pass
                if self.latest() is None:
                    raise CalibrationError(f"car {self.car.id}: Motive does not show its rigid body "
                                           f"{self.car.body_id} (tracked)")
                self.out(f"car {self.car.id}: straight on at {speed:.2f} m/s for about {self.room_m:.1f} m, "
                         "then stop ...")
                self.drive(straight_legs(speed, self.room_m), bus)
                self.out(f"car {self.car.id}: turning standing ...")
                self.drive(turn_legs(turn_rate), bus)
                turned = self._turned()
                if turned < TURNS_IN_PLACE_RAD:
                    vehicle = self.fleet.vehicle
                    circle_speed = min(speed, 0.3)
                    self.out(f"car {self.car.id}: it does not turn standing; a circle at full lock ...")
                    self.drive(circle_legs(circle_speed, vehicle.min_turn_radius_m), bus)
        finally:
            self.sender.close()  # STOP datagrams, an E_STOP kept
            if bus is not None:
                bus.close()
        return calibrate(self.car.id, self.legs, np.array(self.samples), self.fleet.vehicle)

    def _turned(self) -> float:
        began = {leg.name: t for leg, t in self.legs}
        with self._lock:
            rows = np.array([s for s in self.samples if began["turn"] <= s[0]])
        return float(np.max(np.abs(np.unwrap(rows[:, 3]) - rows[0, 3]))) if len(rows) else 0.0


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg calibrate", __doc__)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--car", type=int, required=True, help="the car to measure")
    parser.add_argument("--speed", type=float, default=None,
                        help="the straight leg's command, m/s (default: 1.25 x the config's max_speed_mps, to find "
                             "the car's own)")
    parser.add_argument("--room", type=float, default=2.0,
                        help="how far the straight leg may go, m (default 2.0); the car stops when it is 0.5 m "
                             "further than this from where it started")
    parser.add_argument("--out", type=Path, default=None, help="the [vehicle] table goes here (default carN.vehicle.toml)")
    parser.add_argument("--no-bus", action="store_true", help="do not listen for the operator's stop on the bus "
                                                              "(its direct path still latches the car)")
    args = parser.parse_args(argv)
    if not args.room > 0 or (args.speed is not None and not args.speed > 0):
        parser.error("--room and --speed must be > 0")
    fleet = configured("trustfg calibrate", lambda: _load(args.config, args.car))
    stop = threading.Event()
    stop_on_signals(stop)
    speed = args.speed or 1.25 * fleet.vehicle.max_speed_mps
    pattern = configured("trustfg calibrate", lambda: Pattern(fleet, args.car, stop, not args.no_bus, args.room))
    print(f"trustfg calibrate: car {args.car} drives a pattern of about {args.room:.1f} m; trustfg stop or Ctrl-C "
          "stops it", flush=True)
    try:
        result = pattern.run(speed, 1.5 * fleet.vehicle.max_turn_rate_radps)
    except CalibrationError as exc:
        print(f"trustfg calibrate: {exc}; the car is stopped, nothing written", file=sys.stderr)
        return 130 if stop.is_set() else 1
    for line in result.lines():
        print(line)
    out = args.out or Path(f"car{args.car}.vehicle.toml")
    when = time.strftime("%Y-%m-%d %H:%M")
    out.write_text(vehicle_toml(result, result.vehicle(fleet.vehicle), args.config, when))
    print(f"wrote {out}: the car's [vehicle] table")
    return 0


def _load(config: str, car_id: int) -> Scenario:
    from ...agent.scenario_files import load_scenario

    fleet = load_scenario(config)
    fleet.car(car_id)  # ConfigError when there is none
    return fleet
