"""One control tick of a car: the plan and the pose in, a velocity command out.

The car process's velocity loop (fleet.car.velocity_loop, on real time) and the in-process
fleet (fleet.sim.in_process, on simulated time) both command their cars through
:func:`drive`, so the experiments measure the pipeline that drives the cars:

1. STOP when the car may not drive (no start yet, before its departure, arrived), has
   no plan, or does not see itself;
2. else the tracking command for the plan (bridge.trajectory_controller);
3. capped, when ``guard.enabled``, by the proximity guard (agent.guard) against the
   other cars it sees and the map's walls ahead of it. A car the guard holds (a cap under
   HELD_MPS) stands and turns on the spot to where its plan goes: the tracker's turn rate
   is made for a car that moves, and spins one held still (docs/design/links.md, "The
   control tick"). A car-like car held stands, its turn rate 0; one capped drives the
   same curve slower (its turn rate scaled with its speed).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from ..agent.config import Scenario
from ..agent.gp import Plan
from ..agent.guard import speed_cap
from ..agent.world import SignedDistanceField
from .trajectory_controller import STANDSTILL_MPS, track, turn_on_the_spot

HELD_MPS = STANDSTILL_MPS
"""A guard cap below this holds the car: it stands and turns on the spot to where its plan
goes (bridge.trajectory_controller.turn_on_the_spot), not with the plan's curvature it cannot follow."""


@dataclass(frozen=True)
class Command:
    v: float
    omega: float
    stop: bool = False
    """Send STOP (the car may not drive, has no plan, or no pose)."""
    guard_limited: bool = False
    """The guard lowered the tracking speed."""


STOP = Command(0.0, 0.0, stop=True)


def drive(plan: Plan | None, t: float, pose: tuple[float, float, float] | None, may_drive: bool,
          others: Callable[[], Iterable[tuple[float, float, float, float]]], radius_m: float,
          scenario: Scenario, sdf: SignedDistanceField | None, reaction_s: float | None = None) -> Command:
    """The command of a car at ``pose`` (x, y, yaw; None: not seen) following ``plan`` at
    time ``t``; ``others()`` gives the other cars it sees, (x, y, yaw, radius), and is
    asked only when the guard needs it; ``reaction_s``: the guard's reaction time from the
    pose's age and the loop's tick gaps (agent.guard.reaction_time; default the configured
    one)."""
    if pose is None or plan is None or not may_drive:
        return STOP
    v, omega = track(plan, t, pose[0], pose[1], pose[2], scenario.tracking, scenario.vehicle)
    if scenario.guard.enabled:
        t_r = scenario.guard.reaction_s if reaction_s is None else reaction_s
        cap = speed_cap(*pose, radius_m, others(), scenario.guard, scenario.safety, sdf, t_r, omega * t_r)
        if v > cap:
            if cap < HELD_MPS:  # held: stand, and turn to where the plan goes
                return Command(0.0, turn_on_the_spot(plan, t, *pose, scenario.tracking, scenario.vehicle),
                               guard_limited=True)
            if scenario.vehicle.car_like:  # slower on the same curve: its wheels keep their angle
                omega *= cap / v
            return Command(cap, omega, guard_limited=True)
    return Command(v, omega)
