"""Every tunable of trustfg, typed, in one place.

A scenario file is TOML. Its tables map onto the dataclasses below (units in the field
names or docstrings); anything a file leaves out keeps the default written here. A file
with an unknown key, a value of the wrong type or an out-of-range value is refused with a
:class:`ConfigError` naming the offending key, e.g. ``planner.support_states: expected
an integer, got 'many'``.

Layering: built-in defaults <- scenario file <- command-line overrides
(``with_overrides``). A car's own table (``[[cars]]``) holds what differs per car.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field
from typing import Any


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


# ---------------------------------------------------------------------------------------
# The dataclasses
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Obstacle:
    """An axis-aligned rectangle (``kind = "rect"``, corners ``min``/``max``) or a polygon
    (``kind = "polygon"``, ``points`` counter-clockwise or clockwise), in metres."""

    kind: str = "rect"
    min: tuple[float, float] = (0.0, 0.0)
    max: tuple[float, float] = (0.0, 0.0)
    points: tuple[tuple[float, float], ...] = ()

    def validate(self, path: str) -> None:
        if self.kind == "rect":
            if not (self.max[0] > self.min[0] and self.max[1] > self.min[1]):
                raise ConfigError(f"{path}: rect needs max > min on both axes")
        elif self.kind == "polygon":
            if len(self.points) < 3:
                raise ConfigError(f"{path}.points: a polygon needs at least 3 points")
        else:
            raise ConfigError(f"{path}.kind: expected 'rect' or 'polygon', got {self.kind!r}")


@dataclass(frozen=True)
class WorldConfig:
    """The map: a rectangle of free space bounded by walls, with obstacles inside."""

    bounds_m: tuple[float, float, float, float] = (-2.5, -2.5, 2.5, 2.5)
    """x_min, y_min, x_max, y_max of the arena; outside counts as obstacle."""
    resolution_m: float = 0.01
    """Cell size of the signed distance field."""
    obstacles: tuple[Obstacle, ...] = ()

    def validate(self, path: str) -> None:
        x0, y0, x1, y1 = self.bounds_m
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"{path}.bounds_m: need x_max > x_min and y_max > y_min")
        _positive(self.resolution_m, f"{path}.resolution_m")
        for i, obstacle in enumerate(self.obstacles):
            obstacle.validate(f"{path}.obstacles[{i}]")


@dataclass(frozen=True)
class CarConfig:
    """One car of the fleet: where it starts, where it goes and how it may misbehave."""

    id: int
    start: tuple[float, float]
    goal: tuple[float, float]
    route: tuple[tuple[float, float], ...] = ()
    """Optional via points between start and goal (lane centre lines). They only seed the
    first plan and estimate the path length; the optimiser is free to leave them."""
    start_heading_rad: float | None = None
    """Heading at the start; default: towards the first via point (or the goal)."""
    radius_m: float = 0.1
    color: str = ""
    misinformation: float = 0.0
    """Fraction of this car's plan messages that are falsified (see agent.misbehaviour)."""
    false_testimony: bool = False
    """If true, this car's trust reports lie: they swap success and failure evidence
    about every peer (see agent.misbehaviour)."""
    rigid_body: int = 0
    """Its NatNet rigid-body id in Motive; 0 means the same as ``id``."""
    link: str = ""
    """Where its velocity commands go, ``udp://HOST:PORT`` (the car, or mocap_sim)."""
    listen: tuple[str, ...] = ()
    """Zenoh endpoints this car's process listens on, e.g. ``tcp/10.0.0.11:7447``
    (added to ``bus.listen``)."""

    @property
    def body_id(self) -> int:
        return self.rigid_body or self.id

    @property
    def start_heading(self) -> float:
        """Heading at the start: ``start_heading_rad``, else towards the first via point
        (or the goal)."""
        if self.start_heading_rad is not None:
            return self.start_heading_rad
        target = self.route[0] if self.route else self.goal
        return math.atan2(target[1] - self.start[1], target[0] - self.start[0])

    def validate(self, path: str) -> None:
        if not 1 <= self.id <= 255:
            raise ConfigError(f"{path}.id: must be within 1..255, got {self.id}")
        if self.rigid_body < 0:
            raise ConfigError(f"{path}.rigid_body: must be >= 0")
        if self.link:
            parse_udp_address(self.link, f"{path}.link")
        _positive(self.radius_m, f"{path}.radius_m")
        if not 0.0 <= self.misinformation <= 1.0:
            raise ConfigError(f"{path}.misinformation: must be within [0, 1]")


@dataclass(frozen=True)
class SafetyConfig:
    """The distances that keep cars apart, all derived from the cars' radii and one
    required clearance (every component reads them from here):

        breach distance   d_ab     = r_a + r_b + clearance_m           (centres; closer is a breach)
        planner           eps_0,ab = d_ab + peer_margin_m              (proximity hinge, trusted peer)
        planner, walls    eps_obs  = r + clearance_m + obstacle_margin_m  (centre to surface)
        guard             d_stop   = d_ab + guard.stop_margin_m        (must have stopped by then)

    With the default 0.1 m radii: d_ab = 0.3 m, eps_0 = 0.45 m, eps_obs = 0.25 m, d_stop = 0.35 m.
    """

    clearance_m: float = 0.1
    """Required gap between two cars' edges; less is a breach (metrics, trust's safety
    evidence, the dashboard's alerts)."""
    peer_margin_m: float = 0.15
    """What a plan keeps beyond the breach distance from a fully trusted peer's plan:
    room for tracking error and the peer's plan changing before we hear of it."""
    obstacle_margin_m: float = 0.05
    """What a plan keeps beyond the clearance from walls and obstacles."""

    def validate(self, path: str) -> None:
        _positive(self.clearance_m, f"{path}.clearance_m")
        for name in ("peer_margin_m", "obstacle_margin_m"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{path}.{name}: must be >= 0")

    def breach_distance(self, radius_a: float, radius_b: float) -> float:
        """Centre distance below which two cars breach the clearance."""
        return radius_a + radius_b + self.clearance_m

    def epsilon_0(self, radius_a: float, radius_b: float) -> float:
        """eps_0: the proximity hinge's threshold for a fully trusted peer (centres)."""
        return (radius_a + radius_b) + (self.clearance_m + self.peer_margin_m)

    def epsilon_obstacle(self, radius: float) -> float:
        """The obstacle hinge's threshold, centre to surface."""
        return radius + (self.clearance_m + self.obstacle_margin_m)


@dataclass(frozen=True)
class PlannerConfig:
    """The factor graph of one car (docs/architecture.md, "The planner"). Sigmas are the standard
    deviations of each factor's noise model: smaller means stiffer."""

    support_states: int = 21
    """N, the number of support states x_i = (p_i, v_i) of a plan."""
    interp_checks: int = 4
    """Obstacle/proximity checks per interval in addition to the support state itself."""
    qc: float = 0.5
    """Power spectral density of the white-noise-on-acceleration prior, m^2/s^3."""
    min_horizon_s: float = 2.0
    """A plan never spans less than this, so the last metres are still smooth."""
    cruise_speed_mps: float = 0.4
    """Nominal speed used to set the planned arrival time (a car may override it)."""
    max_speed_mps: float = 0.6
    """Speeds above this are penalised (soft limit; the vehicle's hard limit is higher)."""
    sigma_start: float = 1e-3
    sigma_start_velocity: float = 0.05
    sigma_goal: float = 0.01
    sigma_goal_velocity: float = 0.01
    sigma_obstacle: float = 0.003
    """Walls are certain and do not move; peers' plans are guesses when late, and their
    berth (up to eps_0 * g_max) holds margin. So where both cannot be kept -- a wide berth
    around a predicted peer in a narrow street -- a plan gives way to the peer, by
    (sigma_obstacle / sigma_proximity)^2 ~ 1/11 as much into the wall (the proximity guard
    keeps the cars apart)."""
    sigma_proximity: float = 0.01
    sigma_consistency: float = 0.2
    """Sigma of the consistency residual, in m/s^2."""
    sigma_speed: float = 0.02
    sigma_lane: float = 0.15
    """Sigma of the pull towards the lane centre line, m."""
    max_iterations: int = 30
    relative_error_tol: float = 1e-3
    """LM stops when an iteration lowers the error by less than this fraction; replanning
    is receding-horizon, so the next replan carries on from here."""
    absolute_error_tol: float = 0.05
    """... or by less than this much cost (1/2 sum of squared whitened residuals)."""
    lambda_initial: float = 1e-3
    lambda_factor: float = 10.0
    diagonal_damping: bool = True
    """Damp with lambda * diag(J^T J) (scale-invariant; the hinges are far stiffer than
    the GP prior)."""
    interpolation: str = "batched"
    """'batched': one factor per interval evaluating every check in one numpy call;
    'gtsam': one WnoaInterpFactorPoint2 per interpolated check (slower, for reference)."""
    lane_keeping: bool = True
    """Pull plans towards the car's route (start, via points, goal): its lane."""
    proximity: bool = True
    consistency: bool = True
    transparency: bool = True
    """The three trust factors, switchable for the experiments."""

    def validate(self, path: str) -> None:
        if self.support_states < 3:
            raise ConfigError(f"{path}.support_states: must be at least 3")
        if self.interp_checks < 0:
            raise ConfigError(f"{path}.interp_checks: must be >= 0")
        for name in (
            "qc", "min_horizon_s", "cruise_speed_mps", "max_speed_mps", "sigma_start",
            "sigma_start_velocity", "sigma_goal", "sigma_goal_velocity", "sigma_obstacle",
            "sigma_proximity", "sigma_consistency", "sigma_speed", "sigma_lane", "relative_error_tol", "absolute_error_tol", "lambda_initial",
        ):
            _positive(getattr(self, name), f"{path}.{name}")
        if self.lambda_factor <= 1.0:
            raise ConfigError(f"{path}.lambda_factor: must be > 1")
        if self.max_iterations < 1:
            raise ConfigError(f"{path}.max_iterations: must be >= 1")
        if self.interpolation not in ("batched", "gtsam"):
            raise ConfigError(f"{path}.interpolation: expected 'batched' or 'gtsam'")


@dataclass(frozen=True)
class TrustConfig:
    """Beta reputation per peer and dimension (docs/architecture.md, "Trust")."""

    forgetting: float = 0.85
    """lambda per second: evidence of age s weighs lambda**s (0.85: half-life ~4.3 s)."""
    failure_weight: float = 3.0
    """A failure of transparency or safety counts this many successes: a liar is honest
    most of the time."""
    consistency_failure_weight: float = 1.0
    """A car that did not do what it announced half a second ago counts one failure: cars
    replan, and a changed mind is not a lie."""
    prior_alpha: float = 1.0
    prior_beta: float = 0.0
    """The Beta prior every peer starts from (tau = 2/3); forgetting decays towards it."""
    transparency_tolerance_m: float = 0.15
    """A peer seen within this of where its latest plan says it is now: full success;
    beyond twice this: full failure; linear in between."""
    plan_reject_m: float = 0.30
    """A shared plan that misses the peer's observed position by more than this is not
    planned against; the last plan that agreed (or the observed motion) is used."""
    consistency_tolerance_mps2: float = 0.6
    """Observed vs planned acceleration mismatch that still counts as consistent."""
    evidence_period_s: float = 0.1
    stale_after_s: float = 1.0
    """A peer with no plan for this long is predicted from its observed motion and
    kept at the widest epsilon; silence is never counted as lying."""
    testimony_deviation: float = 0.3
    """A testimony whose mean differs from our own direct estimate by more than this (once
    we hold enough direct evidence) is rejected as a lie and counted."""
    testimony_min_evidence: float = 5.0
    epsilon_gain_max: float = 2.0
    """g(tau) ranges from 1 (tau >= tau_full) to this (tau <= tau_floor)."""
    tau_full: float = 0.9
    tau_floor: float = 0.5

    def validate(self, path: str) -> None:
        if not 0.0 < self.forgetting <= 1.0:
            raise ConfigError(f"{path}.forgetting: must be within (0, 1]")
        if self.prior_alpha < 0 or self.prior_beta < 0:
            raise ConfigError(f"{path}.prior_alpha/prior_beta: must be >= 0")
        if not 0.0 <= self.tau_floor < self.tau_full <= 1.0:
            raise ConfigError(f"{path}.tau_floor/tau_full: need 0 <= tau_floor < tau_full <= 1")
        if self.failure_weight <= 0 or self.consistency_failure_weight <= 0:
            raise ConfigError(f"{path}.failure_weight/consistency_failure_weight: must be > 0")
        if self.epsilon_gain_max < 1.0:
            raise ConfigError(f"{path}.epsilon_gain_max: must be >= 1")
        for name in (
            "transparency_tolerance_m", "plan_reject_m", "consistency_tolerance_mps2",
            "evidence_period_s", "stale_after_s", "testimony_deviation",
        ):
            _positive(getattr(self, name), f"{path}.{name}")


@dataclass(frozen=True)
class VehicleConfig:
    """Unicycle limits of a car (hard limits of the vehicle model and the controller)."""

    max_speed_mps: float = 0.8
    max_reverse_mps: float = 0.0
    max_accel_mps2: float = 1.5
    max_turn_rate_radps: float = 3.0
    max_turn_accel_radps2: float = 12.0

    def validate(self, path: str) -> None:
        for name in ("max_speed_mps", "max_accel_mps2", "max_turn_rate_radps",
                     "max_turn_accel_radps2"):
            _positive(getattr(self, name), f"{path}.{name}")
        if self.max_reverse_mps < 0:
            raise ConfigError(f"{path}.max_reverse_mps: must be >= 0")


@dataclass(frozen=True)
class GuardConfig:
    """The car process's last line of defence (bridge.guard): whatever the plan says, a car
    never drives faster than it can stop before another car seen ahead of it, or a wall.
    Off in the in-process experiments, which measure the planner's own factors."""

    enabled: bool = True
    stop_margin_m: float = 0.05
    """How far beyond the breach distance (SafetyConfig) a car must have stopped, for pose
    noise and latency (stopping right at the breach line breached it by 3 mm in a
    partition run)."""
    decel_mps2: float = 1.0
    """Braking the guard counts on (below the vehicle's max_accel_mps2, for margin)."""
    reaction_s: float = 0.1
    """Pose age plus command latency the guard allows for before braking starts."""
    cone_deg: float = 60.0
    """Another car counts as ahead within this angle of the heading, either side."""
    wall_clearance_m: float = 0.05
    """Gap between the car's edge and a wall at which it must have stopped."""

    def validate(self, path: str) -> None:
        _positive(self.decel_mps2, f"{path}.decel_mps2")
        for name in ("stop_margin_m", "reaction_s", "wall_clearance_m"):
            if getattr(self, name) < 0:
                raise ConfigError(f"{path}.{name}: must be >= 0")
        if not 0.0 < self.cone_deg <= 180.0:
            raise ConfigError(f"{path}.cone_deg: must be within (0, 180]")


@dataclass(frozen=True)
class TrackingConfig:
    """Gains of the unicycle trajectory-tracking controller (bridge.tracking)."""

    k_along: float = 1.5
    """1/s, gain on the along-track error."""
    k_cross: float = 6.0
    """1/m^2-ish, gain on the cross-track error (scaled by reference speed)."""
    k_heading: float = 3.0
    """1/s, gain on the heading error."""
    goal_tolerance_m: float = 0.05
    """A car is at its goal (and at any resting point of its plan) when it sees itself
    this close; it then stops. The one goal tolerance of trustfg (Scenario.arrival_radius_m
    derives the judge's from it)."""

    def validate(self, path: str) -> None:
        for name in ("k_along", "k_cross", "k_heading", "goal_tolerance_m"):
            _positive(getattr(self, name), f"{path}.{name}")


@dataclass(frozen=True)
class ControlConfig:
    """The rhythm of a car: how often it commands, replans, reports (both simulations and
    the lab)."""

    command_rate_hz: float = 50.0
    replan_period_s: float = 0.2
    trust_report_period_s: float = 0.5
    pose_period_s: float = 0.05
    """How often a car publishes its own pose on the bus."""
    status_period_s: float = 0.5
    pose_timeout_s: float = 0.2
    """A car whose own pose is older than this is commanded to stop."""
    start_timeout_s: float = 0.0
    """Drive without a start message after this long (0: wait for one forever)."""

    def validate(self, path: str) -> None:
        for name in ("command_rate_hz", "replan_period_s", "trust_report_period_s", "pose_period_s",
                     "status_period_s", "pose_timeout_s"):
            _positive(getattr(self, name), f"{path}.{name}")
        if self.start_timeout_s < 0:
            raise ConfigError(f"{path}.start_timeout_s: must be >= 0")


@dataclass(frozen=True)
class BusConfig:
    """How a process joins the fleet's Zenoh network (docs/architecture.md, "The bus").

    Simulation and tests: explicit TCP endpoints on 127.0.0.1 and multicast scouting off.
    Lab: multicast scouting on the Wi-Fi interface, listed endpoints, or a router
    (``mode = "client"`` with ``connect`` naming it). ``zenoh_config`` names a JSON5 file
    (deploy/zenoh/) used as the base -- TLS, access control -- that the fields here
    complete.
    """

    mode: str = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    multicast_scouting: bool = False
    multicast_interface: str = ""
    zenoh_config: str = ""
    queue_size: int = 4096
    """Received samples waiting for the agent; beyond this the oldest are dropped (counted)."""

    def validate(self, path: str) -> None:
        if self.mode not in ("peer", "client"):
            raise ConfigError(f"{path}.mode: expected 'peer' or 'client', got {self.mode!r}")
        for name in ("listen", "connect"):
            for i, endpoint in enumerate(getattr(self, name)):
                if "/" not in endpoint:
                    raise ConfigError(f"{path}.{name}[{i}]: not a Zenoh endpoint (like tcp/10.0.0.2:7447): {endpoint!r}")
        if self.queue_size < 16:
            raise ConfigError(f"{path}.queue_size: must be >= 16")


@dataclass(frozen=True)
class NatNetConfig:
    """Where the poses come from: OptiTrack Motive (or mocap_sim) over NatNet."""

    server: str = "127.0.0.1"
    """Address of the Motive host (its command port answers the handshake)."""
    mode: str = "multicast"
    """'multicast' (Motive's default) or 'unicast'."""
    multicast_group: str = "239.255.42.99"
    command_port: int = 1510
    data_port: int = 1511
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


@dataclass(frozen=True)
class SimConfig:
    """Both simulations: the in-process fleet (fleet.fleet_sim, which steps physics and
    control at ``control.command_rate_hz``) and the departures ``trustfg sim`` draws."""

    observation_noise_m: float = 0.002
    message_latency_s: float = 0.02
    timeout_s: float = 45.0
    start_delay_max_s: float = 2.0
    """Each car waits U(0, this) before it moves: desynchronised starts per seed. On the
    intersection's right-hand lanes two crossing cars that start together reach their
    crossing 0.8 m (about 2 s) apart, so real conflicts need offsets of that size: with
    2 s, 30 of 40 seeds breach with avoidance off."""
    cruise_speed_range_mps: tuple[float, float] = (0.35, 0.45)
    """Each car's cruise speed is drawn from this range per seed."""

    def validate(self, path: str) -> None:
        _positive(self.timeout_s, f"{path}.timeout_s")
        if self.observation_noise_m < 0 or self.message_latency_s < 0 or self.start_delay_max_s < 0:
            raise ConfigError(f"{path}: noise, latency and delay must be >= 0")
        lo, hi = self.cruise_speed_range_mps
        if not 0 < lo <= hi:
            raise ConfigError(f"{path}.cruise_speed_range_mps: need 0 < low <= high")


@dataclass(frozen=True)
class Scenario:
    """A whole fleet on a map: what ``--scenario FILE`` loads."""

    name: str
    cars: tuple[CarConfig, ...]
    fleet: str = "demo"
    world: WorldConfig = field(default_factory=WorldConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    trust: TrustConfig = field(default_factory=TrustConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    guard: GuardConfig = field(default_factory=GuardConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    bus: BusConfig = field(default_factory=BusConfig)
    natnet: NatNetConfig = field(default_factory=NatNetConfig)

    def validate(self, path: str = "") -> None:
        prefix = f"{path}." if path else ""
        if not self.cars:
            raise ConfigError(f"{prefix}cars: a scenario needs at least one car")
        ids = [car.id for car in self.cars]
        if len(set(ids)) != len(ids):
            raise ConfigError(f"{prefix}cars: car ids must be unique, got {ids}")
        for i, car in enumerate(self.cars):
            car.validate(f"{prefix}cars[{i}]")
        bodies = [car.body_id for car in self.cars]
        if len(set(bodies)) != len(bodies):
            raise ConfigError(f"{prefix}cars: rigid-body ids must be unique, got {bodies}")
        for name in ("world", "safety", "planner", "trust", "vehicle", "tracking", "guard", "sim", "control", "bus", "natnet"):
            getattr(self, name).validate(prefix + name)

    def car(self, car_id: int) -> CarConfig:
        for car in self.cars:
            if car.id == car_id:
                return car
        raise ConfigError(f"cars: no car with id {car_id} (have {[c.id for c in self.cars]})")

    @property
    def arrival_radius_m(self) -> float:
        """How close to its goal the judge (metrics on ground truth) counts a car as
        arrived: twice the car's own goal tolerance -- the car stops once it *sees* itself
        within the tolerance, so its true position may be off by pose error and braking."""
        return 2.0 * self.tracking.goal_tolerance_m

    def car_colors(self) -> list[str]:
        """Every car's colour (matplotlib names): its own, else the next of PALETTE."""
        return [car.color or PALETTE[i % len(PALETTE)] for i, car in enumerate(self.cars)]


PALETTE = ("tab:blue", "tab:green", "tab:red", "tab:orange", "tab:purple", "tab:brown", "tab:pink",
           "tab:olive", "tab:cyan", "tab:gray")
"""Colours of cars that do not name their own, in order (figures and the dashboard)."""


def with_overrides(obj: Any, **changes: Any) -> Any:
    """A copy of a config dataclass with some fields replaced, validated again."""
    new = dataclasses.replace(obj, **changes)
    if hasattr(new, "validate"):
        new.validate(type(new).__name__)
    return new


def parse_udp_address(text: str, path: str = "address") -> tuple[str, int]:
    """``udp://HOST:PORT`` -> (host, port); ConfigError otherwise."""
    if not text.startswith("udp://"):
        raise ConfigError(f"{path}: expected udp://HOST:PORT, got {text!r}")
    host, _, port = text[len("udp://"):].rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{path}: expected udp://HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


def _positive(value: float, path: str) -> None:
    if not value > 0:
        raise ConfigError(f"{path}: must be > 0, got {value}")
