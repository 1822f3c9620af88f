"""How a car runs: its body's limits, its controller and guard, its rhythm, and its links
(the fleet bus, NatNet)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from .checks import ConfigError, positive

STEERING = ("in-place", "car")
"""What can steer a car (VehicleConfig.steering)."""


@dataclass(frozen=True)
class VehicleConfig:
    """A car's body: what steers it and its limits (hard limits of the vehicle model and the
    controller). A car that turns in place is a unicycle; a car that steers its front wheels
    is a kinematic bicycle (agent.vehicle), which turns only while it moves, no tighter than
    ``min_turn_radius_m``. docs/lab-guide.md, "Car-like cars", says how to choose and how
    ``trustfg calibrate`` measures a car."""

    steering: str = "in-place"
    """What steers the car: 'in-place' (wheels driven at different speeds: it turns on the
    spot, within the turn-rate limits below) or 'car' (front wheels that steer: it turns
    only while it moves, on a radius of at least ``min_turn_radius_m``, and never in
    place; its plans curve no tighter and start along its heading)."""
    min_turn_radius_m: float = 0.3
    """'car': the tightest circle the car's centre drives at full steering lock, in m
    (its curvature limit is 1 / this). Unused for 'in-place'."""
    wheelbase_m: float = 0.15
    """'car': from the rear axle to the front axle, in m. The car's firmware turns a
    commanded (v, omega) into a steering angle delta = atan(wheelbase_m omega / v), at most
    atan(wheelbase_m / min_turn_radius_m) either way (docs/carlink.md). Unused for 'in-place'."""
    max_speed_mps: float = 0.8
    """Fastest a car drives forwards."""
    max_reverse_mps: float = 0.0
    """Fastest a car drives backwards; 0: it never reverses."""
    max_accel_mps2: float = 1.5
    """Largest change of speed per second, speeding up or braking."""
    max_turn_rate_radps: float = 3.0
    """Fastest a car turns."""
    max_turn_accel_radps2: float = 12.0
    """Largest change of turn rate per second."""

    @property
    def car_like(self) -> bool:
        """Does the car steer its front wheels (``steering = "car"``): no turning in place?"""
        return self.steering == "car"

    @property
    def max_curvature(self) -> float:
        """The tightest curvature the car drives, 1/m: 1 / ``min_turn_radius_m`` for a car-like
        car, inf for one that turns in place."""
        return 1.0 / self.min_turn_radius_m if self.car_like else math.inf

    @property
    def max_steer_rad(self) -> float:
        """The steering angle at full lock, atan(wheelbase_m / min_turn_radius_m), rad."""
        return math.atan(self.wheelbase_m / self.min_turn_radius_m)

    def validate(self, path: str) -> None:
        for name in ("max_speed_mps", "max_accel_mps2", "max_turn_rate_radps",
                     "max_turn_accel_radps2", "min_turn_radius_m", "wheelbase_m"):
            positive(getattr(self, name), f"{path}.{name}")
        if self.max_reverse_mps < 0:
            raise ConfigError(f"{path}.max_reverse_mps: must be >= 0")
        if self.steering not in STEERING:
            raise ConfigError(f"{path}.steering: expected one of {', '.join(map(repr, STEERING))}, "
                              f"got {self.steering!r}")


@dataclass(frozen=True)
class TrackingConfig:
    """Gains of the unicycle trajectory-tracking controller (bridge.trajectory_controller)."""

    k_along: float = 1.5
    """Gain on the along-track error, in 1/s."""
    k_cross: float = 6.0
    """Gain on the cross-track error, scaled by the reference speed, in 1/m^2."""
    k_heading: float = 3.0
    """Gain on the heading error, scaled by the reference speed, in 1/m."""
    goal_tolerance_m: float = 0.05
    """A car is at its goal (and at any resting point of its plan) when it sees itself
    this close; it then stops. The one goal tolerance of trustfg (Scenario.arrival_radius_m
    derives the judge's from it)."""
    turn_first_deg: float = 60.0
    """A car facing further than this from where its plan goes turns on the spot before it
    drives (after a stop, say), or drives on at full lock if it is car-like; its peers
    expect that of it (agent.consistency)."""

    def turns_first(self, heading_error_rad: float) -> bool:
        """Does a car this far (wrapped to [-pi, pi]) from its plan's direction turn on the
        spot before it drives? The tracker's rule (bridge.trajectory_controller), and what its peers
        expect of it."""
        return abs(heading_error_rad) > math.radians(self.turn_first_deg)

    def validate(self, path: str) -> None:
        for name in ("k_along", "k_cross", "k_heading", "goal_tolerance_m", "turn_first_deg"):
            positive(getattr(self, name), f"{path}.{name}")


@dataclass(frozen=True)
class GuardConfig:
    """The proximity guard (agent.guard), in every control tick of both simulations and the
    lab: whatever the plan says, a car never drives faster than it can stop before another
    car seen ahead of it, or a wall. The experiments' ablations switch it off."""

    enabled: bool = True
    """Off: a car's commands are not capped by the guard."""
    stop_margin_m: float = 0.05
    """How far beyond the breach distance (SafetyConfig) a car must have stopped, for pose
    noise and latency."""
    decel_mps2: float = 1.0
    """Braking the guard counts on (below the vehicle's max_accel_mps2, for margin)."""
    reaction_s: float = 0.1
    """Pose age plus command latency the guard allows for before braking starts, at least
    (the car process measures both and uses more when they are longer)."""
    command_hold_max_s: float = 0.25
    """The longest a command stays in force without a newer one: the car's watchdog (the
    car link's receiver stops the car 250 ms after its last command). Bounds the measured
    reaction time of a control loop that stalls."""
    cone_deg: float = 60.0
    """Another car counts as ahead within this angle of the heading, either side."""
    wall_clearance_m: float = 0.05
    """Gap between the car's edge and a wall at which it must have stopped."""

    def validate(self, path: str) -> None:
        positive(self.decel_mps2, f"{path}.decel_mps2")
        for name in ("stop_margin_m", "reaction_s", "command_hold_max_s", "wall_clearance_m"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{path}.{name}: must be >= 0")
        if not 0.0 < self.cone_deg <= 180.0:
            raise ConfigError(f"{path}.cone_deg: must be within (0, 180]")


@dataclass(frozen=True)
class ControlConfig:
    """The rhythm of a car: how often it commands, replans, reports (both simulations and
    the lab)."""

    command_rate_hz: float = 50.0
    """How often a car's velocity command is computed and sent (the in-process fleet steps
    physics and control at this rate too)."""
    replan_period_s: float = 0.2
    """How often a car replans."""
    plan_period_s: float = 0.1
    """How often a car publishes its latest plan (best effort: each supersedes the last).
    More often than it replans, so that a peer still gets one within a second when most
    are lost: at 50 % loss, P(no plan in 1 s) = 0.5^10 = 0.1 %."""
    laps: int = 1
    """How many times a car drives its route: lap 2 goes back from the goal to the start,
    lap 3 out again, ... (a long run for soak tests; 1 in the lab)."""
    lap_turn_s: float = 2.0
    """Between laps a car turns in place towards its next leg for this long, then drives (a
    car-like car stands this long: its next plan turns it round as it drives)."""
    trust_report_period_s: float = 0.5
    """How often a car publishes its trust report: its direct evidence about every peer,
    the testimony its peers fuse."""
    pose_period_s: float = 0.05
    """How often a car publishes its own pose on the bus."""
    status_period_s: float = 0.5
    """How often a car publishes its status (mode and counters); a change of mode goes out
    at once."""
    pose_timeout_s: float = 0.2
    """A car whose own pose is older than this is commanded to stop."""
    start_timeout_s: float = 0.0
    """Drive without a start message after this long (0: wait for one forever)."""
    link_ping_period_s: float = 0.5
    """How often the car process PINGs its car (bridge.carlink.answer): whether the link
    answers, and whether the car's e-stop is latched."""
    retry_s: float = 2.0
    """Pause between attempts to reach Motive or to open the bus while a car process starts
    (it keeps its car stopped meanwhile)."""
    lease_s: float = 1.0
    """The command loop (fleet.car.velocity_loop, a process of its own) drives the car only on a
    permit from the car process younger than this: an agent that hangs or dies stops its
    car within it. Longer than a replan on a loaded machine (the main loop renews the
    permit between replans)."""
    realtime_priority: int = 10
    """SCHED_FIFO priority of the command loop where the OS grants it (root, or an
    RLIMIT_RTPRIO); 0: normal scheduling."""

    def validate(self, path: str) -> None:
        for name in ("command_rate_hz", "replan_period_s", "plan_period_s", "trust_report_period_s",
                     "pose_period_s", "status_period_s", "pose_timeout_s", "lap_turn_s",
                     "link_ping_period_s", "retry_s", "lease_s"):
            positive(getattr(self, name), f"{path}.{name}")
        if self.laps < 1:
            raise ConfigError(f"{path}.laps: must be >= 1")
        if not 0 <= self.realtime_priority <= 99:
            raise ConfigError(f"{path}.realtime_priority: must be 0 (off) to 99")
        if self.start_timeout_s < 0:
            raise ConfigError(f"{path}.start_timeout_s: must be >= 0")


@dataclass(frozen=True)
class OperatorConfig:
    """The operator's hold on the fleet (docs/design/architecture.md, "Start and stop"): trials,
    the deadman and the bring-up check. Lab configs switch the deadman on."""

    deadman_s: float = 0.0
    """A car stops (its trial is aborted, it waits for a new start) when no heartbeat of
    an operator's session (``trustfg go``, the dashboard in operator mode, the launcher)
    has arrived for this long, and takes a start only while it hears one. 0: off."""
    heartbeat_period_s: float = 0.1
    """How often an operator's session publishes its heartbeat."""
    rejoin_trial: bool = False
    """A car process that comes up after its departure time (restarted by its supervisor)
    joins the running trial from the operator's cached start. False: it waits for the
    operator to start it again."""
    release_s: float = 0.8
    """How long a car process's datagrams carry RELEASE after the operator released it
    (while it waits), and the operator's tools send their own RELEASE straight to a
    version-2 link (a car latches per sender), seconds: longer than an operator's e-stop repeats on the link (0.5 s,
    fleet.operator.estop_direct), so a repeat still in flight cannot latch the car again, and enough
    datagrams (40 at 50 Hz) that losing some does not matter."""
    clock_tolerance_s: float = 0.02
    """``trustfg check`` warns when a car computer's clock is further than this from the
    operator's (plans and departures carry absolute times)."""

    def validate(self, path: str) -> None:
        if self.deadman_s < 0:
            raise ConfigError(f"{path}.deadman_s: must be >= 0 (0 switches the deadman off)")
        positive(self.heartbeat_period_s, f"{path}.heartbeat_period_s")
        positive(self.clock_tolerance_s, f"{path}.clock_tolerance_s")
        if self.deadman_s and self.deadman_s < 2 * self.heartbeat_period_s:
            raise ConfigError(f"{path}.deadman_s: must be at least twice heartbeat_period_s "
                              f"({self.heartbeat_period_s} s), or 0")
        if not 0.1 <= self.release_s <= 10.0:
            raise ConfigError(f"{path}.release_s: must be within [0.1, 10] s")


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the fleet's Zenoh network (docs/design/architecture.md, "The bus (Zenoh)").

    Simulation and tests: explicit TCP endpoints on 127.0.0.1 and multicast scouting off.
    Lab: multicast scouting on the Wi-Fi interface, listed endpoints, or a router
    (``mode = "client"`` with ``connect`` naming it). ``zenoh_config`` names a JSON5 file
    (deploy/zenoh/) used as the base -- TLS, access control -- that the fields here
    complete: endpoints are added to the file's; mode and multicast scouting come from the
    file when it sets them, and a value here that contradicts the file is an error
    (fleet.bus.zenoh_setup.zenoh_config). Without multicast scouting a session opens at once (no
    scouting delay).
    """

    mode: str = "peer"
    """'peer': processes talk to each other directly; 'client': through the Zenoh router
    named in ``connect``."""
    listen: tuple[str, ...] = ()
    """Zenoh endpoints every process of the fleet listens on, e.g. ``tcp/10.0.0.11:7447``."""
    connect: tuple[str, ...] = ()
    """Zenoh endpoints a process connects to: its peers' listening endpoints, or a router."""
    multicast_scouting: bool = False
    """Find peers by Zenoh's multicast scouting; off: only the listed endpoints are used."""
    multicast_interface: str = ""
    """Network interface multicast scouting uses, e.g. ``wlan0``; empty: Zenoh's choice."""
    zenoh_config: str = ""
    """A Zenoh JSON5 config file taken as the base (TLS, access control) that the keys here
    complete; empty: none."""
    queue_size: int = 4096
    """Received samples waiting for the agent; beyond this the oldest are dropped (counted)."""
    max_links: int = 4
    """Zenoh links admitted per peer (``transport/unicast/max_links``). A car listens on a
    TCP endpoint (reliable: trust reports, the start, liveliness) and may add a UDP one
    marked ``?rel=0`` (best effort: plans, poses, status); with links opened both ways that
    is up to four per pair. Zenoh sends each message on the link of its reliability."""

    def validate(self, path: str) -> None:
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"{path}.mode: expected 'peer' or 'client', got {self.mode!r}")
        for name in ("listen", "connect"):
            for i, endpoint in enumerate(getattr(self, name)):
                if "/" not in endpoint:
                    raise ConfigError(f"{path}.{name}[{i}]: not a Zenoh endpoint (like tcp/10.0.0.2:7447): {endpoint!r}")
        if self.queue_size < 16:
            raise ConfigError(f"{path}.queue_size: must be >= 16")
        if self.max_links < 1:
            raise ConfigError(f"{path}.max_links: must be >= 1")


@dataclass(frozen=True)
class NatNetConfig:
    """Where the poses come from: OptiTrack Motive (or mocap_sim) over NatNet."""

    server: str = "127.0.0.1"
    """Address of the Motive host (its command port answers the handshake)."""
    mode: str = "multicast"
    """'multicast' (Motive's default) or 'unicast'."""
    multicast_group: str = "239.255.42.99"
    """The multicast group Motive streams its frames to (mode 'multicast')."""
    command_port: int = 1510
    """Motive's UDP command port: the handshake goes there."""
    data_port: int = 1511
    """The UDP port frames of data arrive on."""
    local_interface: str = "0.0.0.0"
    """Local address to bind and to join the multicast group on."""
    version: str = ""
    """NatNet version of the stream when no SERVERINFO is heard (e.g. "3.1"; the bridge's
    codec says which it decodes); empty: learn it from the handshake."""
    up_axis: str = "y"
    """Motive's up axis: 'y' (default; ground plane = (x, -z)) or 'z'."""

    def validate(self, path: str) -> None:
        if self.mode not in ("multicast", "unicast"):
            raise ConfigError(f"{path}.mode: expected 'multicast' or 'unicast'")
        if self.up_axis not in ("y", "z"):
            raise ConfigError(f"{path}.up_axis: expected 'y' or 'z'")
        if self.version and not re.fullmatch(r"\d{1,3}\.\d{1,3}", self.version):
            raise ConfigError(f"{path}.version: expected MAJOR.MINOR like \"3.1\", got {self.version!r}")
        for name in ("command_port", "data_port"):
            if not 0 <= getattr(self, name) <= 65535:
                raise ConfigError(f"{path}.{name}: not a port number")
