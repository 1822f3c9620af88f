"""Scenes made from a seed (the scenario bank's generator) and the check every scene passes.

    trustfg scenario generate --kind KIND --cars N --seed S [--name NAME] --out FILE
    trustfg scenario check FILE|NAME [...]

Kinds (:data:`KINDS`): ``circle``, ``circle-obstacles``, ``corridor``, ``bottleneck``,
``t-junction``, ``warehouse``, ``random-field``; every size follows the cars' radii
through SafetyConfig (eps_0 between cars, eps_obs from walls). Every car gets a route where
the straight line would not keep its comfort from obstacles. :func:`check_scene` refuses a
start or goal too close to an obstacle, a wall or another car's, and a scene in which a car
is cut off from its goal once the others stand at theirs (:func:`cut_off_by_parked`); the
generator draws again from the seed's stream until a layout passes. A scene's
``sim.timeout_s`` follows its longest route. docs/design/experiments.md, "Scenes from a
seed".
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path
from typing import Callable

import numpy as np

from ...agent.config import CarConfig, ConfigError, Obstacle, SafetyConfig, Scenario, SimConfig, WorldConfig
from ...agent.routes import COMFORT_MARGIN_M, NoRoute, car_route, connected, path_length
from ...agent.scenario_files import dump_scenario, load_scenario
from ...agent.world import SignedDistanceField, build_sdf
from ..program import command_parser, configured

RADIUS_M = CarConfig(id=1, start=(0, 0), goal=(0, 0)).radius_m
"""Generated cars have the default radius."""
TIMEOUT_ROUTE_FACTOR = 2.5
TIMEOUT_SLACK_S = 8.0
"""A scene's timeout: the latest start + this factor x the longest route at the slowest
cruise speed + this slack, rounded up to 5 s."""


@dataclasses.dataclass(frozen=True)
class Layout:
    """What a kind draws: the arena, its obstacles and each car's start and goal."""

    bounds: tuple[float, float, float, float]
    obstacles: tuple[Obstacle, ...]
    trips: tuple[tuple[tuple[float, float], tuple[float, float]], ...]
    text: str
    """One line describing this instance (for the file's header)."""


# --- the kinds ---------------------------------------------------------------------------------


def _distances(safety: SafetyConfig) -> tuple[float, float]:
    return safety.epsilon_0(RADIUS_M, RADIUS_M), safety.epsilon_obstacle(RADIUS_M)


def circle(n: int, rng: np.random.Generator, safety: SafetyConfig, pillars: bool = False) -> Layout:
    eps_0, eps_obs = _distances(safety)
    radius = max(2.0 if pillars else 1.5, n * 2 * eps_0 / (2 * math.pi))
    half = round(radius + eps_obs + 0.35, 2)
    turn = rng.uniform(0.0, 2 * math.pi / n)
    angles = turn + 2 * math.pi * np.arange(n) / n
    trips = tuple((_pt(radius * math.cos(a), radius * math.sin(a)), _pt(-radius * math.cos(a), -radius * math.sin(a)))
                  for a in angles)
    obstacles: list[Obstacle] = []
    placed: list[tuple[np.ndarray, float]] = []
    inner = radius - 1.0
    count = int(rng.integers(1, 4)) if pillars else 0
    for _ in range(200 * count):
        if len(obstacles) == count:
            break
        size = rng.uniform(0.3, min(0.6, 0.6 * inner))
        reach = math.sqrt(rng.uniform()) * (inner - size)
        direction = rng.uniform(0.0, 2 * math.pi)
        centre = np.array([reach * math.cos(direction), reach * math.sin(direction)])
        if all(np.linalg.norm(centre - c) >= size + s + 2 * eps_obs + 0.1 for c, s in placed):
            placed.append((centre, size))
            obstacles.append(_regular_polygon(centre, size, int(rng.integers(4, 9)), rng.uniform(0, math.pi)))
    text = f"{n} cars swap antipodal points of a ring of radius {radius:.2f} m"
    if pillars:
        text += f" around {len(obstacles)} pillar(s) in the middle"
    return Layout((-half, -half, half, half), tuple(obstacles), trips, text)


def passage(n: int, rng: np.random.Generator, safety: SafetyConfig, door: bool = False) -> Layout:
    """Two rooms joined by a corridor (or a door in a wall); half the cars go each way."""
    eps_0, eps_obs = _distances(safety)
    abreast = 2 * eps_obs + eps_0  # two cars side by side, each eps_obs from its wall
    if door:
        width, length = rng.uniform(2 * eps_obs + 0.1, abreast - 0.1), 0.2
    else:
        width, length = rng.uniform(abreast + 0.05, abreast + 0.45), rng.uniform(1.6, 2.4)
    offset = rng.uniform(-0.3, 0.3) if door else 0.0
    per_side = math.ceil(n / 2)
    step = eps_0 + 0.1
    rows = max(2, math.ceil(per_side / 2))
    height = max(width + 2 * abs(offset) + 1.2, rows * step + 2 * (eps_obs + 0.25))
    depth = 2 * step + eps_obs + 0.35
    x_wall, half_h = length / 2, height / 2
    bounds = (-x_wall - depth, -half_h, x_wall + depth, half_h)
    obstacles = (Obstacle(kind="rect", min=_pt(-x_wall, offset + width / 2), max=_pt(x_wall, half_h)),
                 Obstacle(kind="rect", min=_pt(-x_wall, -half_h), max=_pt(x_wall, offset - width / 2)))
    ys = (np.arange(rows) - (rows - 1) / 2) * step
    slots = {side: [_pt(side * (x_wall + step * (k + 1)), y) for y in ys for k in range(2)] for side in (-1, 1)}
    counts = {-1: per_side, 1: n - per_side}

    def pick(side: int, count: int) -> list[tuple[float, float]]:
        return [slots[side][k] for k in rng.permutation(len(slots[side]))[:count]]
    trips = [trip for side in (-1, 1) for trip in zip(pick(side, counts[side]), pick(-side, counts[side]))]
    what = f"a door {width:.2f} m wide in a wall" if door else f"a corridor {width:.2f} m wide and {length:.2f} m long"
    return Layout(bounds, obstacles, tuple(trips),
                  f"two rooms joined by {what}; {per_side} cars go east, {n - per_side} west")


def t_junction(n: int, rng: np.random.Generator, safety: SafetyConfig) -> Layout:
    eps_0, eps_obs = _distances(safety)
    lateral = (eps_0 + 0.1) / 2
    width = rng.uniform(2 * (lateral + eps_obs) + 0.05, 2 * (lateral + eps_obs) + 0.35)
    arm = 2.2
    w, reach = width / 2, width / 2 + arm
    bounds = (-reach, -reach, reach, w)
    obstacles = (Obstacle(kind="rect", min=_pt(-reach, -reach), max=_pt(-w, -w)),
                 Obstacle(kind="rect", min=_pt(w, -reach), max=_pt(reach, -w)))
    ends = {"west": (np.array([-reach, 0.0]), np.array([1.0, 0.0])),
            "east": (np.array([reach, 0.0]), np.array([-1.0, 0.0])),
            "south": (np.array([0.0, -reach]), np.array([0.0, 1.0]))}
    depths = (eps_obs + 0.25, eps_obs + 0.25 + eps_0 + 0.1)
    if n > 4 * len(ends):
        raise ConfigError(f"t-junction: at most {4 * len(ends)} cars")

    def slots(name: str) -> list[tuple[float, float]]:
        end, inward = ends[name]
        side = np.array([-inward[1], inward[0]])
        return [_pt(*(end + d * inward + s * lateral * side)) for d in depths for s in (-1, 1)]
    starts = {name: slots(name) for name in ends}
    goals = {name: slots(name) for name in ends}
    names = list(ends)
    rng.shuffle(names)
    trips = []
    for i in range(n):
        origin = names[i % 3]
        others = [name for name in names if name != origin and goals[name]]
        target = others[int(rng.integers(len(others)))]
        trips.append((starts[origin].pop(0), goals[target].pop(int(rng.integers(len(goals[target]))))))
    return Layout(bounds, obstacles, tuple(trips),
                  f"three roads {width:.2f} m wide meet; each car drives from one road's end to another's")


def warehouse(n: int, rng: np.random.Generator, safety: SafetyConfig) -> Layout:
    eps_0, eps_obs = _distances(safety)
    aisles = 4 if n <= 8 else 5
    # A spot is a bay along one side of an aisle (a parked car leaves room to pass it): an
    # aisle holds a parked car eps_obs off the rack, eps_0 to the passing car and eps_obs to
    # the other rack, plus slack; the cross aisles the same, bays against the outer walls.
    aisle = cross = 2 * eps_obs + eps_0 + 0.25
    rack, rack_len = 0.4, 2.0
    width = aisles * aisle + (aisles - 1) * rack
    half_w, half_h = width / 2, rack_len / 2 + cross
    centres = [-half_w + aisle / 2 + k * (aisle + rack) for k in range(aisles)]
    obstacles = tuple(Obstacle(kind="rect", min=_pt(c + aisle / 2, -rack_len / 2), max=_pt(c + aisle / 2 + rack, rack_len / 2))
                      for c in centres[:-1])
    step, bay = eps_0 + 0.1, eps_obs + 0.02
    spots = [_pt(c - aisle / 2 + bay, y) for c in centres for y in (-step, 0.0, step)]
    spots += [_pt(c, s * (half_h - bay)) for c in centres for s in (-1, 1)]
    if n > len(spots) // 2:
        raise ConfigError(f"warehouse: at most {len(spots) // 2} cars")
    starts = [spots[i] for i in rng.permutation(len(spots))[:n]]
    trips = []
    taken: set = set()
    for start in starts:
        choices = [s for s in spots if abs(s[0] - start[0]) > 1e-6 and s not in taken]
        goal = choices[int(rng.integers(len(choices)))]
        taken.add(goal)
        trips.append((start, goal))
    return Layout((-half_w, -half_h, half_w, half_h), obstacles, tuple(trips),
                  f"{aisles} aisles between {aisles - 1} racks; every car goes to a spot in another aisle")


def random_field(n: int, rng: np.random.Generator, safety: SafetyConfig) -> Layout:
    eps_0, eps_obs = _distances(safety)
    side = round(4.0 + 0.2 * n, 2)
    half = side / 2
    gap = 2 * eps_obs + 0.1  # every gap lets a car through
    obstacles: list[Obstacle] = []
    placed: list[tuple[np.ndarray, float]] = []
    count = int(rng.integers(4, 8))
    for _ in range(500):
        if len(obstacles) == count:
            break
        if rng.uniform() < 0.5:
            w, h = rng.uniform(0.3, 0.9, 2)
            size, shape = math.hypot(w, h) / 2, ("rect", w, h)
        else:
            size, shape = rng.uniform(0.25, 0.5), ("polygon", int(rng.integers(3, 8)))
        centre = rng.uniform(-half + size + gap, half - size - gap, 2)
        if any(np.linalg.norm(centre - c) < size + s + gap for c, s in placed):
            continue
        placed.append((centre, size))
        angle = rng.uniform(0, math.pi)
        if shape[0] == "rect":
            obstacles.append(_rotated_rect(centre, shape[1], shape[2], angle))
        else:
            obstacles.append(_regular_polygon(centre, size, shape[1], angle))
    bounds = (-half, -half, half, half)
    sdf = build_sdf(WorldConfig(bounds_m=bounds, obstacles=tuple(obstacles)))
    trips: list = []
    for _ in range(5000):
        if len(trips) == n:
            break
        start, goal = (rng.uniform(-half + eps_obs, half - eps_obs, 2) for _ in range(2))
        if (np.linalg.norm(goal - start) >= 0.4 * side
                and np.all(sdf.distance(np.stack([start, goal])) >= eps_obs + COMFORT_MARGIN_M)
                and all(np.linalg.norm(start - s) >= eps_0 + 0.1 and np.linalg.norm(goal - g) >= eps_0 + 0.1
                        for s, g in trips)):
            trips.append((start, goal))
    if len(trips) < n:
        raise ConfigError(f"random-field: could not place {n} cars in a {side} m room")
    return Layout(bounds, tuple(obstacles), tuple((_pt(*s), _pt(*g)) for s, g in trips),
                  f"a {side} m square room with {len(obstacles)} random obstacles, random starts and goals")


KINDS: dict[str, Callable[..., Layout]] = {
    "circle": circle,
    "circle-obstacles": lambda n, rng, safety: circle(n, rng, safety, pillars=True),
    "corridor": passage,
    "bottleneck": lambda n, rng, safety: passage(n, rng, safety, door=True),
    "t-junction": t_junction,
    "warehouse": warehouse,
    "random-field": random_field,
}


# --- a whole scene -------------------------------------------------------------------------------


DRAWS = 200
"""Layouts a seed draws, one after another, until one passes :func:`check_scene`."""


def generate(kind: str, cars: int, seed: int, name: str = "") -> tuple[Scenario, str]:
    """The scene of ``kind`` with ``cars`` cars drawn from ``seed``, and its one-line
    description; ConfigError if it cannot be made or fails :func:`check_scene`."""
    if kind not in KINDS:
        raise ConfigError(f"--kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    if not 2 <= cars <= 64:
        raise ConfigError(f"--cars: expected 2..64, got {cars}")
    safety, rng = SafetyConfig(), np.random.default_rng(seed)
    for draw in range(DRAWS):  # the seed's first layout that passes the check
        layout = KINDS[kind](cars, rng, safety)
        world = WorldConfig(bounds_m=tuple(round(b, 3) for b in layout.bounds), obstacles=layout.obstacles)
        sdf = build_sdf(world)
        draft = Scenario(name=name or f"{kind}-{cars}", world=world,
                         cars=tuple(CarConfig(id=i + 1, start=s, goal=g) for i, (s, g) in enumerate(layout.trips)))
        try:
            check_scene(draft, sdf)
            break
        except ConfigError:
            if draw == DRAWS - 1:
                raise
    routed = []
    for car in draft.cars:
        try:
            route = car_route(draft, car, sdf)
        except NoRoute as exc:
            raise ConfigError(f"{kind}, car {car.id}: {exc}") from None
        routed.append(dataclasses.replace(car, route=route))
    longest = max(path_length([c.start, *c.route, c.goal]) for c in routed)
    sim = SimConfig()
    timeout = sim.start_delay_max_s + TIMEOUT_ROUTE_FACTOR * longest / sim.cruise_speed_range_mps[0] + TIMEOUT_SLACK_S
    scenario = dataclasses.replace(draft, cars=tuple(routed),
                                   sim=dataclasses.replace(sim, timeout_s=5.0 * math.ceil(timeout / 5.0)))
    scenario.validate()
    return scenario, layout.text


def check_scene(scenario: Scenario, sdf: SignedDistanceField | None = None) -> None:
    """Raise ConfigError unless every start and goal keeps eps_obs from obstacles and walls
    and eps_0 from every other car's start (goal), and no car parked at its goal cuts
    another off from its own (:func:`cut_off_by_parked`)."""
    sdf = sdf or build_sdf(scenario.world)
    _check_clear(scenario, sdf)
    for car in scenario.cars:
        if cut_off_by_parked(scenario, car, sdf):
            raise ConfigError(f"{scenario.name}: car {car.id} cannot reach its goal {car.goal} from its start "
                              f"{car.start} once the other cars stand at their goals (no gap of eps_0 past them): "
                              "move goals out of the ways")


def scene_problem(scenario: Scenario) -> str | None:
    """What :func:`check_scene` says against ``scenario`` (None: nothing), for the tools
    that run a scene anyway and warn (``trustfg sim``, ``trustfg check``)."""
    try:
        check_scene(scenario)
    except ConfigError as exc:
        return str(exc)
    return None


def cut_off_by_parked(scenario: Scenario, car: CarConfig, sdf: SignedDistanceField) -> bool:
    """Whether ``car``'s way from start to goal, keeping eps_obs from obstacles, is cut once
    every other car stands at its goal, each kept eps_0 off. A car at its goal stays there
    (it is nobody's obstacle to wait for: it will not move), so a scene where one order of
    arrivals cuts a car off ends in a deadlock no planner that keeps eps_0 can resolve
    (the condition of "well-formed" infrastructures in prioritised planning, Cap et al.
    2015, for goals only: a start is left in time). A goal on another car's start is not
    counted for that car: it is reached only after that car has left."""
    safety = scenario.safety
    keep_out = [(other.goal, safety.epsilon_0(car.radius_m, other.radius_m)) for other in scenario.cars
                if other.id != car.id
                and math.dist(other.goal, car.start) >= safety.epsilon_0(car.radius_m, other.radius_m)]
    return not connected(sdf, car.start, car.goal, safety.epsilon_obstacle(car.radius_m) - 1e-6, keep_out)


def _check_clear(scenario: Scenario, sdf: SignedDistanceField) -> None:
    safety = scenario.safety
    for which in ("start", "goal"):
        points = np.array([getattr(car, which) for car in scenario.cars], dtype=float)
        clearance = sdf.distance(points)
        for car, d in zip(scenario.cars, clearance):
            need = safety.epsilon_obstacle(car.radius_m)
            if d < need:
                raise ConfigError(f"{scenario.name}: car {car.id}'s {which} {getattr(car, which)} is {d:.3f} m "
                                  f"from an obstacle or wall (needs {need:.3f} m)")
        for a, car_a in enumerate(scenario.cars):
            for b in range(a + 1, len(scenario.cars)):
                car_b = scenario.cars[b]
                d = float(np.linalg.norm(points[a] - points[b]))
                need = safety.epsilon_0(car_a.radius_m, car_b.radius_m)
                if d < need:
                    raise ConfigError(f"{scenario.name}: the {which}s of cars {car_a.id} and {car_b.id} are "
                                      f"{d:.3f} m apart (need {need:.3f} m)")


def scene_file_text(scenario: Scenario, kind: str, cars: int, seed: int, text: str) -> str:
    command = f"trustfg scenario generate --kind {kind} --cars {cars} --seed {seed} --name {scenario.name}"
    return (f"# {scenario.name}: {text}.\n# Generated, do not edit; regenerate with\n#   {command} --out FILE\n"
            + dump_scenario(scenario, changed_only=True))


def _pt(x: float, y: float) -> tuple[float, float]:
    return (round(float(x), 3), round(float(y), 3))


def _regular_polygon(centre: np.ndarray, radius: float, sides: int, angle: float) -> Obstacle:
    a = angle + 2 * math.pi * np.arange(sides) / sides
    return Obstacle(kind="polygon", points=tuple(_pt(centre[0] + radius * math.cos(t), centre[1] + radius * math.sin(t))
                                                 for t in a))


def _rotated_rect(centre: np.ndarray, w: float, h: float, angle: float) -> Obstacle:
    c, s = math.cos(angle), math.sin(angle)
    corners = [(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)]
    return Obstacle(kind="polygon", points=tuple(_pt(centre[0] + c * x - s * y, centre[1] + s * x + c * y)
                                                 for x, y in corners))


# --- command line ------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg scenario", __doc__)
    sub = parser.add_subparsers(dest="action", required=True)
    gen = sub.add_parser("generate", help="make a scene from a seed", formatter_class=parser.formatter_class,
                         description="Make a scene from a seed: a map of KIND with CARS cars whose starts and "
                                     "goals pass the scene check, written as a scenario file.")
    gen.add_argument("--kind", required=True, choices=list(KINDS), help="the kind of map")
    gen.add_argument("--cars", type=int, required=True, help="number of cars (2..64; some kinds hold fewer)")
    gen.add_argument("--seed", type=int, default=0, help="draws the scene (default 0)")
    gen.add_argument("--name", default="", help="the scene's name (default: KIND-CARS)")
    gen.add_argument("--out", type=Path, required=True, help="the TOML file to write")
    check = sub.add_parser("check", help="check that starts and goals are clear of obstacles and each other",
                           formatter_class=parser.formatter_class,
                           description="Check scenes: every start and goal clear of the obstacles and of each other.")
    check.add_argument("scenes", nargs="+", help="scenario files or shipped scene names")
    args = parser.parse_args(argv)
    if args.action == "generate":
        scenario, text = configured("trustfg scenario", lambda: generate(args.kind, args.cars, args.seed, args.name))
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(scene_file_text(scenario, args.kind, args.cars, args.seed, text))
        print(f"wrote {args.out}: {text}; timeout {scenario.sim.timeout_s:.0f} s")
        return 0
    for source in args.scenes:
        scenario = configured("trustfg scenario", lambda: load_scenario(source))
        configured("trustfg scenario", lambda: check_scene(scenario))
        print(f"{source}: {len(scenario.cars)} cars, starts and goals clear")
    return 0


if __name__ == "__main__":
    sys.exit(main())
