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

import math
from dataclasses import dataclass, field

from .attacks import ATTACKS, PAPER_LIAR, AttackConfig, liar_attack, parse_attack
from .checks import ConfigError, parse_id_values, parse_udp_address, positive, with_overrides
from .planning import DeadlockConfig, PlannerConfig, TrustConfig, VerifyConfig
from .running import (
    BusConfig,
    ControlConfig,
    GuardConfig,
    NatNetConfig,
    OperatorConfig,
    TrackingConfig,
    VehicleConfig,
)
from .scene import CarConfig, Obstacle, SafetyConfig, SensingConfig, SimConfig, WorldConfig, check_range, guard_needs_m

__all__ = [
    "ConfigError", "parse_udp_address", "positive", "with_overrides", "PlannerConfig", "TrustConfig",
    "VerifyConfig", "DeadlockConfig",
    "BusConfig", "ControlConfig", "GuardConfig", "NatNetConfig", "OperatorConfig", "TrackingConfig", "VehicleConfig",
    "CarConfig", "Obstacle", "SafetyConfig", "SimConfig", "WorldConfig", "Scenario", "PALETTE", "SensingConfig",
    "ATTACKS", "AttackConfig", "PAPER_LIAR", "liar_attack", "parse_attack", "parse_id_values",
]


@dataclass(frozen=True)
class Scenario:
    """A whole fleet on a map: what ``--scenario FILE`` loads."""

    name: str
    """The scenario's name, shown in logs, records and figures."""
    cars: tuple[CarConfig, ...]
    """The cars of the fleet, one ``[[cars]]`` table each; at least one."""
    fleet: str = "demo"
    """The fleet's name: its processes talk on Zenoh keys under it, so two fleets on one
    network do not hear each other."""
    world: WorldConfig = field(default_factory=WorldConfig)
    """The map: arena bounds and obstacles."""
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    """Each car's factor graph and its optimiser."""
    trust: TrustConfig = field(default_factory=TrustConfig)
    """Each car's trust in its peers: evidence, testimonies, the audit of plans."""
    verify: VerifyConfig = field(default_factory=VerifyConfig)
    """The check of every plan before a car uses or publishes it, and the fallback."""
    deadlock: DeadlockConfig = field(default_factory=DeadlockConfig)
    """How cars that block each other are found and which gives way."""
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    """The required clearance and the margins plans keep beyond it."""
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    """The cars' speed, acceleration and turn-rate limits."""
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    """The trajectory-tracking controller's gains and goal tolerance."""
    guard: GuardConfig = field(default_factory=GuardConfig)
    """The car process's last line of defence: braking for cars and walls ahead."""
    sensing: SensingConfig = field(default_factory=SensingConfig)
    """How far a car sees its peers: everywhere (the motion capture), or within a range."""
    sim: SimConfig = field(default_factory=SimConfig)
    """Both simulations: sensor noise, message delays and losses, departures."""
    control: ControlConfig = field(default_factory=ControlConfig)
    """A car's rhythm: how often it commands, replans and publishes."""
    bus: BusConfig = field(default_factory=BusConfig)
    """How a process joins the fleet's Zenoh network."""
    natnet: NatNetConfig = field(default_factory=NatNetConfig)
    """Where poses come from: OptiTrack Motive, or mocap_sim, over NatNet."""
    operator: OperatorConfig = field(default_factory=OperatorConfig)
    """The operator's hold on the fleet: the deadman, restarts, the release, clock checks."""

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
        for name in ("world", "safety", "planner", "trust", "verify", "deadlock", "vehicle", "tracking", "guard", "sim",
                     "control", "bus", "natnet", "operator", "sensing"):
            getattr(self, name).validate(prefix + name)
        if self.safety.peer_margin_m < self.trust.transparency_tolerance_m:
            # A liar can bias its plans by anything under the tolerance unnoticed (it reads
            # as pose noise); the margin every plan keeps beyond the breach distance must
            # cover that bias, or an undetectable lie could lead a peer into a breach.
            raise ConfigError(f"{prefix}safety.peer_margin_m ({self.safety.peer_margin_m}) must be at least "
                              f"trust.transparency_tolerance_m ({self.trust.transparency_tolerance_m}): the margin "
                              "must cover what a liar can bias its plans by unnoticed")
        if self.guard.enabled:  # the guard sees what the car sees: far enough to stop in time
            largest = max(car.radius_m for car in self.cars)
            needs = guard_needs_m(self.safety.breach_distance(largest, largest), self.guard.stop_margin_m,
                                  self.vehicle.max_speed_mps, self.guard.reaction_s, self.guard.decel_mps2)
            check_range(self.sensing.range_m, needs, f"{prefix}sensing.range_m")
            for i, car in enumerate(self.cars):
                check_range(car.sensing_range_m, needs, f"{prefix}cars[{i}].sensing_range_m")
        if self.operator.deadman_s and self.control.start_timeout_s:
            raise ConfigError(f"{prefix}control.start_timeout_s: a car cannot drive without a start while "
                              f"operator.deadman_s asks it to hear the operator (set one of them to 0)")

    @property
    def liars(self) -> list[int]:
        """Ids of the cars that run an attack."""
        return [car.id for car in self.cars if car.attack is not None]

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

    def sensing_range(self, car: CarConfig) -> float:
        """How far ``car`` sees its peers, m (inf: everywhere): its own ``sensing_range_m``,
        else ``sensing.range_m``."""
        chosen = car.sensing_range_m if car.sensing_range_m is not None else self.sensing.range_m
        return math.inf if chosen is None else chosen

    def car_colors(self) -> list[str]:
        """Every car's colour (matplotlib names): its own, else the next of PALETTE."""
        return [car.color or PALETTE[i % len(PALETTE)] for i, car in enumerate(self.cars)]


PALETTE = ("tab:blue", "tab:green", "tab:red", "tab:orange", "tab:purple", "tab:brown", "tab:pink",
           "tab:olive", "tab:cyan", "tab:gray")
"""Colours of cars that do not name their own, in order (figures and the dashboard)."""
