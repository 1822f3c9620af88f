"""Geometry of a car that steers its front wheels: the turns it can make, and the paths it cannot.

A car-like car (VehicleConfig.steering = "car") turns only while it moves, on a radius
of at least R_min, and never reverses. These questions come up again and again:

* :func:`departure_arc` -- which turn takes a car standing at a heading round to face a
  point (the start of a cold plan, a detour): a circular arc at radius R towards the side
  the point lies on (the other side when the point lies inside that turning circle);
  :func:`turn_then` puts it in front of a way on (the length that sets an arrival);
* :func:`turning_excess` -- does a path turn tighter than a car starting at a heading can
  drive (verification): along the path's arc length s its heading phi(s), the car's own
  at s = 0, must keep |phi(s_b) - phi(s_a)| <= (s_b - s_a) / R + slack for every s_a < s_b;
* :func:`ways_on` -- which ways a car that stands can set off on at all (a car boxed in
  by cars that stand: agent.deadlock);
* :func:`initial_headings` -- the heading variables a plan's support states start from in
  the factor graph (agent.heading_factors); :func:`held_to` -- what a car's plans and
  detours are held to.

Pure functions of numpy arrays. docs/design/planner.md, "Car-like cars".
"""

from __future__ import annotations

import math

import numpy as np

from .config import VehicleConfig

ARC_STEP_RAD = math.radians(10.0)
"""A departure arc's points lie this far apart in heading."""
MOVING_MPS = 0.02
"""A support state slower than this names no heading: it keeps the one before."""


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def departure_arc(position: np.ndarray, heading: float, target: np.ndarray, radius: float,
                  step_rad: float = ARC_STEP_RAD) -> np.ndarray:
    """Points (k, 2) of the arc at ``radius`` that turns a car at ``position`` facing
    ``heading`` until it faces ``target``, every ``step_rad`` of heading, ``position``
    left out; empty when it faces ``target`` within half a step already.

    The arc turns towards the side ``target`` lies on; when ``target`` lies inside that
    side's turning circle (no arc of that side ever faces it), towards the other side,
    the long way round."""
    position = np.asarray(position, float)
    target = np.asarray(target, float)
    offset = target - position
    if float(np.hypot(*offset)) < 1e-9:
        return np.zeros((0, 2))
    bearing = wrap(math.atan2(offset[1], offset[0]) - heading)
    if abs(bearing) <= step_rad / 2:
        return np.zeros((0, 2))
    side = 1.0 if bearing > 0 else -1.0
    left = np.array([-math.sin(heading), math.cos(heading)])
    centre = position + radius * side * left
    if float(np.hypot(*(target - centre))) < radius:
        side = -side
        centre = position + radius * side * left
    points = []
    h = heading
    for _ in range(int(math.ceil(2 * math.pi / step_rad))):
        h += side * step_rad
        p = centre + radius * side * np.array([math.sin(h), -math.cos(h)])
        points.append(p)
        to_target = target - p
        before, bearing = bearing, wrap(math.atan2(to_target[1], to_target[0]) - h)
        crossed = before * side > 0 >= bearing * side and abs(bearing) < math.pi / 2  # through zero, not round pi
        if abs(bearing) <= step_rad / 2 or crossed:
            break
    return np.array(points)


def turn_then(way: np.ndarray, heading: float, radius: float) -> np.ndarray:
    """The way (k, 2) from where a car-like car stands (way[0]), facing ``heading``, with
    the departure arc first that turns it to face the way's first point beyond its
    turning circle's width (the last point when none is), that point on."""
    way = np.asarray(way, float)
    beyond = np.flatnonzero(np.linalg.norm(way - way[0], axis=1) > 2.0 * radius)
    first = int(beyond[0]) if len(beyond) else len(way) - 1
    return np.vstack([way[:1], departure_arc(way[0], heading, way[first], radius), way[first:]])


def ways_on(position: np.ndarray, heading: float, radius: float, step_m: float = 0.02) -> list[np.ndarray]:
    """The three ways a car-like car standing at ``position``, facing ``heading``, can set
    off on: a quarter turn left and one right at ``radius``, and straight on for the width
    of its turning circle -- each points (k, 2) every ``step_m``, ``position`` left out.
    A car none of them is open to cannot move without coming nearer what blocks them: it
    can neither turn in place nor back away."""
    position = np.asarray(position, float)
    forward = np.array([math.cos(heading), math.sin(heading)])
    left = np.array([-forward[1], forward[0]])
    straight = position + np.arange(1, int(math.ceil(2.0 * radius / step_m)) + 1)[:, None] * step_m * forward
    turned = np.arange(1, int(math.ceil(0.5 * math.pi * radius / step_m)) + 1) * step_m / radius  # rad
    arcs = [position + radius * (np.sin(turned)[:, None] * forward + side * (1.0 - np.cos(turned))[:, None] * left)
            for side in (1.0, -1.0)]
    return [*arcs, straight]


def turning_excess(points: np.ndarray, heading: float | None, radius: float, slack_rad: float,
                   spacing_m: float) -> tuple[float, int]:
    """How far (rad) the path through ``points`` (k, 2), driven from ``heading`` (None: the
    path's own first direction), turns beyond what a car of minimum turning ``radius`` can
    follow, less ``slack_rad``; and the index of the point where it is worst (-inf, 0 when
    the path does not move).

    The path is taken every ``spacing_m`` of its length; each chord's direction phi_j
    stands at its middle s_j, the start heading at s = 0. A car can drive it when
    phi_b - phi_a <= (s_b - s_a) / R + slack for every a < b, both ways round: the largest
    rise of phi_j - s_j / R (and of -phi_j - s_j / R) over any earlier value is at most the
    slack. A reversal at a standstill turns pi over no length."""
    points = np.asarray(points, float)
    if len(points) < 2:
        return -math.inf, 0
    steps = np.hypot(*np.diff(points, axis=0).T)
    travelled = np.concatenate([[0.0], np.cumsum(steps)])
    if travelled[-1] < spacing_m:
        return -math.inf, 0
    # Every spacing_m of length: the first point of each bin, and the last.
    bins = np.floor(travelled / spacing_m).astype(int)
    kept = np.flatnonzero(np.concatenate([[True], np.diff(bins) > 0]))
    if kept[-1] != len(points) - 1:
        kept = np.append(kept, len(points) - 1)
    chord = np.diff(points[kept], axis=0)
    length = np.hypot(chord[:, 0], chord[:, 1])
    moving = length > 1e-9
    chord, where, index = chord[moving], (travelled[kept][:-1] + length / 2)[moving], kept[:-1][moving]
    phi = np.arctan2(chord[:, 1], chord[:, 0])
    if heading is not None:
        phi = np.concatenate([[heading], phi])
        where = np.concatenate([[0.0], where])
        index = np.concatenate([[0], index])
    phi = np.unwrap(phi)
    worst, at = -math.inf, 0
    for sign in (1.0, -1.0):
        x = sign * phi - where / radius
        rise = x - np.minimum.accumulate(x)
        k = int(np.argmax(rise))
        if rise[k] > worst:
            worst, at = float(rise[k]), int(index[k])
    return worst - slack_rad, at


def initial_headings(velocities: np.ndarray, heading: float) -> np.ndarray:
    """A heading per support state (n,) to start the optimiser from: ``heading`` first,
    then each state's direction of motion, unwrapped onto the one before; a state slower
    than MOVING_MPS keeps the one before."""
    out = np.empty(len(velocities))
    current = heading
    for i, v in enumerate(np.asarray(velocities, float)):
        if i > 0 and math.hypot(v[0], v[1]) >= MOVING_MPS:
            current = current + wrap(math.atan2(v[1], v[0]) - current)
        out[i] = current
    return out


def held_to(vehicle: VehicleConfig, yaw: float) -> tuple[float, float] | None:
    """(heading, minimum turning radius) of a car-like car facing ``yaw``: what its plans
    and detours are held to (agent.planner.PlanRequest.steering, agent.deadlock); None for
    a car that turns in place."""
    return (yaw, vehicle.min_turn_radius_m) if vehicle.car_like else None
