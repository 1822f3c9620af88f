"""The proximity guard: a speed cap from the poses the car sees and the map, under any plan.

A car never drives faster than it can stop short of another car seen within
``cone_deg`` of its heading, at distance d, or of a wall ahead:

    v t_r + v^2 / (2 a) <= d - d_stop     (reaction distance + braking distance)
    =>  v_max = a (-t_r + sqrt(t_r^2 + 2 (d - d_stop) / a)),   0 once d <= d_stop

with a = ``decel_mps2``, t_r the reaction time (:func:`reaction_time`) and d_stop the
pair's breach distance (SafetyConfig) + ``stop_margin_m``. Head on, each car may use
half the gap; a car beside caps the part of the speed that closes in on it; for a wall,
d - d_stop is the room straight ahead (ray-marched). Turning is never limited.
docs/design/safety.md, "The proximity guard".
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from .config import GuardConfig, SafetyConfig
from .world import SignedDistanceField

RAY_STEP_M = 0.02
RAY_LENGTH_M = 1.5
"""Beyond the stopping distance from any speed the car can reach (0.8 m/s: 0.4 m)."""
RAY_STEPS = np.arange(1, int(RAY_LENGTH_M / RAY_STEP_M) + 1) * RAY_STEP_M
"""Distances ahead of the centre at which a ray is checked (the guard asks at every tick)."""
TURN_STEP_RAD = math.radians(15.0)
"""A turning car is checked at headings this far apart over its turn."""


def reaction_time(pose_age_s: float, tick_gap_s: float, config: GuardConfig) -> float:
    """t_r = max(reaction_s, pose age + min(tick gap, command_hold_max_s)): how long the car
    may go on at the commanded speed after the pose the command was computed from."""
    return max(config.reaction_s, max(pose_age_s, 0.0) + min(max(tick_gap_s, 0.0), config.command_hold_max_s))


def speed_cap(x: float, y: float, yaw: float, radius_m: float,
              others: Iterable[tuple[float, float, float, float]], config: GuardConfig,
              safety: SafetyConfig, sdf: SignedDistanceField | None = None,
              reaction_s: float | None = None, turn_rad: float = 0.0) -> float:
    """The highest forward speed from which the car of ``radius_m`` at (x, y, yaw) still
    stops short of every car (x, y, yaw, radius) in ``others`` ahead of it and, given the
    map's ``sdf``, of every wall ahead (inf when nothing is ahead); ``reaction_s`` (default
    ``config.reaction_s``) before braking starts, and at the heading yaw + ``turn_rad`` too
    (where a turning car points when the next command takes effect)."""
    t_r = config.reaction_s if reaction_s is None else reaction_s
    others = list(others)
    steps = math.ceil(abs(turn_rad) / TURN_STEP_RAD)  # the sweep, every TURN_STEP_RAD or finer
    headings = [yaw + turn_rad * k / max(steps, 1) for k in range(steps + 1)]
    walls = [math.inf] * len(headings) if sdf is None else _wall_caps(x, y, headings, radius_m, config, sdf, t_r)
    return min(_cap_at(x, y, heading, radius_m, others, config, safety, wall, t_r)
               for heading, wall in zip(headings, walls))


def capped_below(x: float, y: float, yaw: float, radius_m: float,
                 others: Iterable[tuple[float, float, float, float]], config: GuardConfig,
                 safety: SafetyConfig, sdf: SignedDistanceField | None, speed: float) -> bool:
    """``speed_cap(x, y, yaw, radius_m, others, config, safety, sdf) < speed``, the same
    answer at less cost: the cap is a minimum of terms >= 0, so a speed <= 0 is never
    above it, and the walls' ray march (the dearest term) is left out when a car ahead
    already holds the speed down. For a truster asking of every peer ten times a second
    whether its guard holds it (agent.consistency)."""
    if not speed > 0.0:
        return False
    t_r = config.reaction_s
    if _cap_at(x, y, yaw, radius_m, list(others), config, safety, math.inf, t_r) < speed:
        return True
    return sdf is not None and _wall_caps(x, y, [yaw], radius_m, config, sdf, t_r)[0] < speed


def _wall_caps(x: float, y: float, headings: list[float], radius_m: float, config: GuardConfig,
               sdf: SignedDistanceField, t_r: float) -> list[float]:
    """The walls' term of the cap at each heading: stop before the ray ahead comes within
    the clearance (every heading's ray in one march)."""
    return [stopping_speed(room, config, t_r)
            for room in wall_rooms(x, y, headings, sdf, radius_m + config.wall_clearance_m)]


def _cap_at(x: float, y: float, yaw: float, radius_m: float, others: list[tuple[float, float, float, float]],
            config: GuardConfig, safety: SafetyConfig, wall_cap: float, t_r: float) -> float:
    """The cap at one heading: the others' terms and ``wall_cap``, the walls' (inf: none)."""
    cap = wall_cap
    cos_cone = math.cos(math.radians(config.cone_deg))
    c, s = math.cos(yaw), math.sin(yaw)
    for ox, oy, oyaw, oradius in others:
        dx, dy = ox - x, oy - y
        d = math.hypot(dx, dy)
        reach = safety.breach_distance(radius_m, oradius) + config.stop_margin_m
        along = dx * c + dy * s
        if d > 0.0 and along / d < cos_cone:  # beside or behind
            if along > 0.0:  # beside: we close in at v along / d, and that part must stop in time
                cap = min(cap, stopping_speed(d - reach, config, t_r) * d / along)
            continue
        room = d - reach
        if d > 0.0 and -(dx * math.cos(oyaw) + dy * math.sin(oyaw)) / d >= cos_cone:
            room /= 2.0  # it faces us too: we share the gap
        cap = min(cap, stopping_speed(room, config, t_r))
    return cap


def stopping_speed(room: float, config: GuardConfig, t_r: float) -> float:
    """v_max = a (-t_r + sqrt(t_r^2 + 2 room / a)): reaction plus braking distance = room."""
    if room <= 0.0:
        return 0.0
    if math.isinf(room):
        return math.inf
    a = config.decel_mps2
    return a * (-t_r + math.sqrt(t_r * t_r + 2.0 * room / a))


def wall_room(x: float, y: float, yaw: float, sdf: SignedDistanceField, keep_m: float) -> float:
    """How far the centre can go straight ahead before it comes closer to a wall than
    ``keep_m`` (or than it is now, if nearer); inf if free for RAY_LENGTH_M."""
    return wall_rooms(x, y, [yaw], sdf, keep_m)[0]


def wall_rooms(x: float, y: float, headings: list[float], sdf: SignedDistanceField, keep_m: float) -> list[float]:
    """:func:`wall_room` at each of ``headings``, the rays marched together (the same
    numbers: the field is sampled point by point)."""
    directions = np.array([[math.cos(h), math.sin(h)] for h in headings])
    rays = np.array([x, y]) + RAY_STEPS[None, :, None] * directions[:, None, :]
    limit = min(keep_m, float(sdf.distance(np.array([x, y]))) - 1e-3)
    blocked = sdf.distance(rays) < limit
    first = blocked.argmax(axis=1)
    return [float(RAY_STEPS[i] - RAY_STEP_M) if row[i] else math.inf for row, i in zip(blocked, first.tolist())]
