"""ORCA, the baseline a user would pick instead, driving the same simulated cars.

ORCA (van den Berg et al., "Reciprocal n-body collision avoidance", ISRR 2009) through
pyrvo, bindings of the RVO2 library, with perfect state (every car's true position and
velocity) and no messages; its cars are the in-process fleet's unicycles with the same
limits, departures and cruise speeds (fleet.sim.in_process.draw_departures). Each step a
car's preferred velocity points at its next via point (slowing into the goal, with RVO2's
seeded 1e-4 m/s perturbation); ORCA steers the point P = p + L h ahead of the car (L its
radius; a unicycle can move P in any direction), and its velocity u for P becomes

    v = max(0, u . h),    omega = (u . h_perp) / L

clamped by the vehicle's limits. The agent radius, max(eps_0 / 2, L + r + clearance / 2),
keeps two cars the required clearance apart. docs/design/experiments.md, "ORCA".
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...agent.config import Obstacle, Scenario
from ...agent.routes import car_route
from ...agent.vehicle import VehicleState
from ...agent.vehicle import step as vehicle_step
from ...agent.world import SignedDistanceField, build_sdf
from .in_process import draw_departures
from .run_record import RunRecord

NEIGHBOR_DIST_M = 3.0
TIME_HORIZON_S = 2.0
TIME_HORIZON_OBST_S = 1.0
GOAL_SLOWDOWN_S = 1.0
VIA_REACHED_M = 0.3
PERTURBATION_MPS = 1e-4


class MissingLibrary(RuntimeError):
    """pyrvo is not installed."""


def _pyrvo():
    try:
        import pyrvo
    except ImportError:
        raise MissingLibrary("the ORCA baseline needs pyrvo: pip install -e '.[baselines]'") from None
    return pyrvo


def simulate_orca(scenario: Scenario, seed: int, sdf: SignedDistanceField | None = None) -> RunRecord:
    """Run the scenario with ORCA driving every car, to completion or sim.timeout_s."""
    pyrvo = _pyrvo()
    sdf = sdf or build_sdf(scenario.world)
    rng = np.random.default_rng(seed)
    depart, cruise = draw_departures(scenario, rng)
    perturb = np.random.default_rng([seed, 11])
    cars = list(scenario.cars)
    n = len(cars)
    step_s = 1.0 / scenario.control.command_rate_hz
    max_speed = scenario.planner.max_speed_mps
    radius = [orca_radius(scenario, car.radius_m) for car in cars]
    sim = pyrvo.RVOSimulator(step_s, NEIGHBOR_DIST_M, n, TIME_HORIZON_S, TIME_HORIZON_OBST_S, radius[0], max_speed)
    for car, r in zip(cars, radius):
        agent = sim.add_agent(tuple(car.start))
        sim.set_agent_radius(agent, r)
    for polygon in _obstacle_polygons(scenario):
        sim.add_obstacle(polygon)
    sim.process_obstacles()

    vehicles = [VehicleState(c.start[0], c.start[1], c.start_heading) for c in cars]
    waypoints = [np.array([*car_route(scenario, c, sdf), c.goal], dtype=float) for c in cars]
    target = [0] * n
    goals = np.array([c.goal for c in cars], dtype=float)
    stopped = [False] * n
    steps = int(math.ceil(scenario.sim.timeout_s / step_s)) + 1
    times, states, step_ms = [], [], []
    arrived: list[float | None] = [None] * n
    for k in range(steps):
        t = k * step_s
        times.append(t)
        states.append([[s.x, s.y, s.yaw, s.v, s.omega] for s in vehicles])
        for i, state in enumerate(vehicles):
            centre = np.array([state.x, state.y])
            heading = np.array([math.cos(state.yaw), math.sin(state.yaw)])
            lead = cars[i].radius_m
            point = centre + lead * heading
            to_goal = float(np.linalg.norm(centre - goals[i]))
            if arrived[i] is None and to_goal <= scenario.arrival_radius_m:
                arrived[i] = t
            stopped[i] = stopped[i] or to_goal <= scenario.tracking.goal_tolerance_m
            sim.set_agent_position(i, (float(point[0]), float(point[1])))
            velocity = state.v * heading + lead * state.omega * np.array([-heading[1], heading[0]])
            sim.set_agent_velocity(i, (float(velocity[0]), float(velocity[1])))
            preferred = np.zeros(2)
            if t >= depart[i] and not stopped[i]:
                target[i] = _next_waypoint(sim, point, waypoints[i], target[i], radius[i])
                last = target[i] == len(waypoints[i]) - 1
                aim = waypoints[i][target[i]] + (lead * heading if last else 0.0)
                to = aim - point
                distance = float(np.linalg.norm(to))
                speed = min(cruise[i], distance / GOAL_SLOWDOWN_S) if last else cruise[i]
                angle = perturb.uniform(0.0, 2 * math.pi)
                preferred = to / max(distance, 1e-9) * speed + PERTURBATION_MPS * np.array([math.cos(angle), math.sin(angle)])
            sim.set_agent_pref_velocity(i, (float(preferred[0]), float(preferred[1])))
        started = time.perf_counter()
        sim.do_step()
        step_ms.append((time.perf_counter() - started) * 1e3)
        for i, state in enumerate(vehicles):
            if t < depart[i] or stopped[i]:
                v_cmd, w_cmd = 0.0, 0.0
            else:
                u = sim.get_agent_velocity(i)
                v_cmd, w_cmd = unicycle_command(u.x, u.y, state.yaw, cars[i].radius_m)
            vehicles[i] = vehicle_step(state, v_cmd, w_cmd, step_s, scenario.vehicle)
        if all(a is not None for a in arrived) and all(abs(s.v) < 1e-3 for s in vehicles):
            break

    per_car_ms = [m / n for m in step_ms]
    empty = np.zeros((0, n, n))
    return RunRecord(
        seed=seed, car_ids=[c.id for c in cars], radii=[c.radius_m for c in cars],
        times=np.array(times), states=np.array(states), arrived_at=arrived,
        depart_at=[float(d) for d in depart], trust_times=np.zeros(0), trust=empty, transparency=empty,
        epsilon=empty, replan_ms=[per_car_ms] * n, counters=[{} for _ in cars], inbox=[{} for _ in cars],
    )


def unicycle_command(ux: float, uy: float, yaw: float, lead: float) -> tuple[float, float]:
    """The (v, omega) that moves the point ``lead`` ahead of a car heading ``yaw`` with
    velocity u (module doc); never backwards."""
    c, s = math.cos(yaw), math.sin(yaw)
    return max(0.0, ux * c + uy * s), (-ux * s + uy * c) / lead


def orca_radius(scenario: Scenario, radius: float) -> float:
    """ORCA's agent radius about a car's lead point (module doc)."""
    safety = scenario.safety
    return max(safety.epsilon_0(radius, radius) / 2, 2 * radius + safety.clearance_m / 2)


def _next_waypoint(sim, position: np.ndarray, waypoints: np.ndarray, index: int, radius: float) -> int:
    while index < len(waypoints) - 1 and (
            np.linalg.norm(waypoints[index] - position) <= VIA_REACHED_M
            or sim.query_visibility(tuple(position), tuple(waypoints[index + 1]), radius)):
        index += 1
    return index


def _obstacle_polygons(scenario: Scenario) -> list[list[tuple[float, float]]]:
    """Every obstacle counter-clockwise, and the arena's walls as a clockwise boundary."""
    polygons = [_counter_clockwise(_vertices(o)) for o in scenario.world.obstacles]
    x0, y0, x1, y1 = scenario.world.bounds_m
    polygons.append([(x0, y0), (x0, y1), (x1, y1), (x1, y0)])  # clockwise: the cars are inside
    return polygons


def _vertices(obstacle: Obstacle) -> list[tuple[float, float]]:
    if obstacle.kind == "rect":
        (ax, ay), (bx, by) = obstacle.min, obstacle.max
        return [(ax, ay), (bx, ay), (bx, by), (ax, by)]
    return [tuple(p) for p in obstacle.points]


def _counter_clockwise(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    xs, ys = np.array(points).T
    area = 0.5 * float(np.sum(xs * np.roll(ys, -1) - np.roll(xs, -1) * ys))
    return points if area > 0 else points[::-1]
