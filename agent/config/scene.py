"""The scene: the map, the cars on it, the distances that keep them apart, and how far cars see."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .attacks import AttackConfig
from .checks import ConfigError, parse_udp_address, positive


@dataclass(frozen=True)
class Obstacle:
    """An axis-aligned rectangle (``kind = "rect"``, corners ``min``/``max``) or a polygon
    (``kind = "polygon"``, ``points`` counter-clockwise or clockwise), in metres."""

    kind: str = "rect"
    """'rect' or 'polygon'."""
    min: tuple[float, float] = (0.0, 0.0)
    """A rect's lower-left corner (x, y), in m."""
    max: tuple[float, float] = (0.0, 0.0)
    """A rect's upper-right corner (x, y), in m."""
    points: tuple[tuple[float, float], ...] = ()
    """A polygon's corners (x, y) in order, in m; at least three."""

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
    """Obstacles inside the arena: rects and polygons."""

    def validate(self, path: str) -> None:
        x0, y0, x1, y1 = self.bounds_m
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"{path}.bounds_m: need x_max > x_min and y_max > y_min")
        positive(self.resolution_m, f"{path}.resolution_m")
        for i, obstacle in enumerate(self.obstacles):
            obstacle.validate(f"{path}.obstacles[{i}]")


@dataclass(frozen=True)
class CarConfig:
    """One car of the fleet: where it starts, where it goes and how it may misbehave."""

    id: int
    """The car's id, 1 to 255: its name on the bus, in logs and figures, and its rigid body
    in Motive unless ``rigid_body`` names another."""
    start: tuple[float, float]
    """Where the car starts (x, y), in m."""
    goal: tuple[float, float]
    """Where the car goes (x, y), in m."""
    route: tuple[tuple[float, float], ...] = ()
    """Optional via points (x, y) between start and goal (lane centre lines), in m. They only
    seed the first plan and estimate the path length; the optimiser is free to leave them."""
    start_heading_rad: float | None = None
    """Heading at the start; default: towards the first via point (or the goal)."""
    radius_m: float = 0.1
    """The car's radius; every safety distance follows it (SafetyConfig)."""
    color: str = ""
    """The car's colour in figures and on the dashboard, a matplotlib name; empty: the
    next of a fixed palette."""
    attack: AttackConfig | None = None
    """How this car lies (experiments only; agent.attacks, config.attacks); none: honest."""
    clock_offset_s: float = 0.0
    """Simulation and tests only: this car's clock runs this far ahead of the fleet's (both
    simulations add it to every time the car reads). In the lab a clock is what NTP makes
    it, and this stays 0."""
    rigid_body: int = 0
    """Its NatNet rigid-body id in Motive; 0 means the same as ``id``."""
    link: str = ""
    """Where its velocity commands go, ``udp://HOST:PORT`` (the car, or mocap_sim)."""
    link_version: int = 2
    """Car-link version: 2, authenticated with the car's key (link_key_file); 1 only for
    old firmware that cannot check a MAC (anyone on the network can then drive the car)."""
    link_key_file: str = ""
    """File holding the car's 32-byte link key as 64 hex digits (owner-readable only; never
    commit one). Needed for link_version 2."""
    link_key: str = ""
    """The key inline, as 64 hex digits -- for throw-away runs only; prefer link_key_file."""
    listen: tuple[str, ...] = ()
    """Zenoh endpoints this car's process listens on, e.g. ``tcp/10.0.0.11:7447``
    (added to ``bus.listen``)."""
    simulated: bool = True
    """Whether mocap-sim simulates this car. false: a real car among simulated ones (a
    mixed fleet): mocap-sim binds no link for it and relays its rigid body from the real
    motion capture (``trustfg mocap-sim --relay``). Car processes never read it."""
    sensing_range_m: float | None = None
    """How far this car sees its peers, in m (SensingConfig.range_m); not set: the fleet's
    ``sensing.range_m``."""

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
        if self.link_version not in (1, 2):
            raise ConfigError(f"{path}.link_version: expected 1 or 2, got {self.link_version}")
        if self.link_version == 1 and (self.link_key or self.link_key_file):
            raise ConfigError(f"{path}: link_version 1 does not use a key; drop the key or use version 2")
        if self.link_key and (len(self.link_key) != 64 or any(c not in "0123456789abcdefABCDEF" for c in self.link_key)):
            raise ConfigError(f"{path}.link_key: expected 64 hexadecimal digits")
        positive(self.radius_m, f"{path}.radius_m")
        if self.attack is not None:
            self.attack.validate(f"{path}.attack")
        if self.sensing_range_m is not None:
            positive(self.sensing_range_m, f"{path}.sensing_range_m")
        if not abs(self.clock_offset_s) <= 60.0:
            raise ConfigError(f"{path}.clock_offset_s: must be within [-60, 60] s")


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
        positive(self.clearance_m, f"{path}.clearance_m")
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

    def obstacle_breach(self, radius: float) -> float:
        """Centre-to-surface distance below which a car breaches the clearance to a wall."""
        return radius + self.clearance_m


@dataclass(frozen=True)
class SimConfig:
    """Both simulations: the in-process fleet (fleet.sim.in_process, which steps physics and
    control at ``control.command_rate_hz``) and the departures ``trustfg sim`` draws."""

    observation_noise_m: float = 0.002
    """In-process fleet: the standard deviation of the Gaussian noise added to every pose
    observation, per axis (seeded)."""
    message_latency_s: float = 0.02
    """In-process fleet: every fleet message arrives this late, plus its jitter."""
    message_jitter_s: float = 0.0
    """In-process fleet: every fleet message arrives a further U(0, this) late, in order per
    sender and receiver (seeded per run)."""
    message_loss: float = 0.0
    """In-process fleet: the probability that a message is lost for a receiver (seeded)."""
    timeout_s: float = 45.0
    """A simulated run ends after this long, every car arrived or not (``trustfg sim``
    allows this per lap, and some slack)."""
    start_delay_max_s: float = 2.0
    """Each car waits U(0, this) before it moves: desynchronised starts per seed. Two
    crossing cars that start together on the intersection's right-hand lanes reach their
    crossing about 2 s apart, so real conflicts need offsets of that size."""
    cruise_speed_range_mps: tuple[float, float] = (0.35, 0.45)
    """Each car's cruise speed is drawn from this range per seed."""
    replan_phase_max_s: float | None = None
    """In-process fleet: each car's replans fall U(0, this) into the replan period (not set:
    the whole period, as car processes started one by one do). 0: every car replans at
    the same instants -- two cars set off together at the same speed then see each other
    alike, the tie no phase breaks (a door one car wide: both stand)."""
    settle_s: float = 2.0
    """Cars stand this long at their starts, seeing and hearing each other, before the
    go: ``trustfg sim`` gives the go no sooner after the last car came up, and the
    in-process fleet starts this long before its go. Strangers are planned around with
    the widest epsilon (eps_0 x g_max at the prior's lower bound): cars that start closer
    than that would plan away from each other at the go and fail each other's
    consistency; two seconds of standing plans seen to come true lift every peer off the
    prior by the go (a lab's operator gives it later still)."""

    def validate(self, path: str) -> None:
        positive(self.timeout_s, f"{path}.timeout_s")
        if (self.observation_noise_m < 0 or self.message_latency_s < 0 or self.message_jitter_s < 0
                or self.start_delay_max_s < 0 or self.settle_s < 0
                or (self.replan_phase_max_s is not None and self.replan_phase_max_s < 0)):
            raise ConfigError(f"{path}: noise, latency, jitter and delay must be >= 0")
        if not 0.0 <= self.message_loss < 1.0:
            raise ConfigError(f"{path}.message_loss: must be within [0, 1)")
        lo, hi = self.cruise_speed_range_mps
        if not 0 < lo <= hi:
            raise ConfigError(f"{path}.cruise_speed_range_mps: need 0 < low <= high")


@dataclass(frozen=True)
class SensingConfig:
    """How far a car sees its peers (docs/design/trust.md, "Limited sight"). The motion
    capture sees every car everywhere; a car on a road sees only its neighbours. With a
    range set, a car's mind receives the poses of the peers within it only (both
    simulations and the car process filter what the motion capture hands it), and so does
    its proximity guard (docs/design/safety.md, "Limited sight"). Peers out of sight are
    planned against from their shared plans at the epsilon of the trust fused from the
    testimonies of the cars that see them, never as if fully trusted."""

    range_m: float | None = None
    """A car sees the peers whose centres are within this distance of its own, in m; not
    set: every peer, wherever it is (the motion capture's view). A car's own
    ``sensing_range_m`` replaces it for that car. At least what the proximity guard needs
    to stop for a car coming head on at the vehicle's top speed (:func:`guard_needs_m`; a
    shorter range is refused)."""
    line_of_sight: bool = False
    """With a range: a peer behind a wall of the map (the straight line between the two
    centres crosses an obstacle) is out of sight too. Without a range it changes nothing."""

    def validate(self, path: str) -> None:
        if self.range_m is not None:
            positive(self.range_m, f"{path}.range_m")


def guard_needs_m(breach_m: float, stop_margin_m: float, speed_mps: float, reaction_s: float,
                  decel_mps2: float) -> float:
    """The distance at which the proximity guard (agent.guard) must see a peer coming head on,
    both at ``speed_mps``, to stop both in time: each may use half the gap beyond the
    breach distance and the stop margin, and needs its reaction plus braking distance

        d = d_ab + stop_margin + 2 (v t_r + v^2 / (2 a))

    (with the defaults, 0.3 + 0.05 + 2 (0.08 + 0.32) = 1.15 m for 0.1 m cars at 0.8 m/s)."""
    return breach_m + stop_margin_m + 2.0 * (speed_mps * reaction_s + speed_mps ** 2 / (2.0 * decel_mps2))


def check_range(range_m: float | None, needs_m: float, path: str) -> None:
    """Refuse a sensing range shorter than what the guard needs (``needs_m``)."""
    if range_m is not None and range_m < needs_m:
        raise ConfigError(f"{path}: {range_m:g} m is shorter than the {needs_m:.2f} m at which the proximity "
                          "guard must see a car coming head on at the vehicle's top speed to stop in time "
                          "(agent.config.scene.guard_needs_m)")
