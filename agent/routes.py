"""Routes: a car's via points round the obstacles of a map (and round cars that stand).

A scene's route is its lane: the planner seeds its first plan along it and is pulled
softly towards it, and the ORCA baseline steers at its next via point. A car whose
straight line keeps ``comfort`` from every obstacle gets none; otherwise the route is
the cheapest path on an 8-connected grid over the free space, a step costing its length
times 1 + NEAR_WEIGHT * clip((comfort - d) / comfort, 0, 1) (routes keep to the middle
of a passage), found by Dijkstra and shortened to the farthest clear via points. Cars
that stand are discs of keep-out searched round the same way (agent.safe_plan,
``around``); :func:`connected` tells whether a way exists at all.
docs/design/planner.md, "Routes".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from .config import CarConfig, Scenario
from .world import SignedDistanceField

KeepOut = tuple[tuple[float, float], float]
"""A disc a route keeps out of: (centre, radius), m."""

GRID_M = 0.05
"""Cell size of the route search, m."""
NEAR_WEIGHT = 3.0
SEGMENT_STEP_M = 0.02
"""Spacing of the distance checks along a straight segment, m."""
COMFORT_MARGIN_M = 0.15
"""A scene's routes keep eps_obs + this from obstacles where they can."""
SNAP_M = 0.1
"""How far a point inside a clearance may be from a free cell and still count as in its
region (connected): a car stopped that little inside can step out."""


class NoRoute(ValueError):
    """No path keeps the required clearance between a start and its goal."""


def segment_clear(sdf: SignedDistanceField, a: np.ndarray, b: np.ndarray, threshold: float) -> bool:
    """Whether every point of the segment a-b is at least ``threshold`` from any obstacle."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    count = max(2, int(np.ceil(np.linalg.norm(b - a) / SEGMENT_STEP_M)) + 1)
    points = a + np.linspace(0.0, 1.0, count)[:, None] * (b - a)
    return bool(np.all(sdf.distance(points) >= threshold))


def connected(sdf: SignedDistanceField, a, b, clearance: float, keep_out: Sequence[KeepOut] = ()) -> bool:
    """Whether a centre can move from ``a`` to ``b`` keeping ``clearance`` from every
    obstacle and ``radius`` from every (point, radius) of ``keep_out``: a and b lie in one
    connected region of the free cells of the distance field's own grid. A point a little
    inside a clearance (a car that stopped 2 cm nearer a wall than eps_obs) counts as in
    the region of the nearest free cell within SNAP_M: it can step out of it."""
    ny, nx = sdf.values.shape
    regions, _ = ndimage.label(free_cells(sdf, clearance, keep_out))
    reach = int(math.ceil(SNAP_M / sdf.cell_m))

    def region(p) -> int:
        ix = int(np.clip(round((p[0] - sdf.origin[0]) / sdf.cell_m), 0, nx - 1))
        iy = int(np.clip(round((p[1] - sdf.origin[1]) / sdf.cell_m), 0, ny - 1))
        if regions[iy, ix]:
            return int(regions[iy, ix])
        y0, x0 = max(iy - reach, 0), max(ix - reach, 0)
        window = regions[y0:iy + reach + 1, x0:ix + reach + 1]
        cells = np.argwhere(window > 0)
        if cells.size == 0:
            return 0
        gap = np.hypot(cells[:, 0] + y0 - iy, cells[:, 1] + x0 - ix) * sdf.cell_m
        nearest = int(np.argmin(gap))
        return int(window[tuple(cells[nearest])]) if gap[nearest] <= SNAP_M else 0
    return region(a) != 0 and region(a) == region(b)


def free_cells(sdf: SignedDistanceField, clearance: float, keep_out: Sequence[KeepOut] = ()) -> np.ndarray:
    """The cells of the distance field's grid (rows y, columns x) that keep ``clearance``
    from every obstacle and lie outside every disc of ``keep_out``:

        d(z) >= clearance  and  (x - c_x)^2 + (y - c_y)^2 >= r^2 for every (c, r)

    Each disc is tested on its own window of the grid (``_disc_window``), the same answer
    as the whole grid's at a fraction of the work: a deadlock watch asks this for a dozen
    parked cars at every replan of a crowded scene."""
    ny, nx = sdf.values.shape
    free = sdf.values >= clearance
    xs = sdf.origin[0] + np.arange(nx) * sdf.cell_m
    ys = sdf.origin[1] + np.arange(ny) * sdf.cell_m
    for (px, py), radius in keep_out:
        rows, cols = _disc_window(sdf, px, py, radius, nx, ny)
        free[rows, cols] &= (xs[None, cols] - px) ** 2 + (ys[rows, None] - py) ** 2 >= radius * radius
    return free


def _disc_window(sdf: SignedDistanceField, px: float, py: float, radius: float, nx: int, ny: int) -> tuple[slice, slice]:
    """The rows and columns of the grid that a keep-out disc can take cells from: its
    bounding box and a cell more each way. A cell outside is farther than |radius| along x
    or y alone, so (dx^2 + dy^2 >= r^2) holds there in floating point too (squaring and
    adding round monotonically): testing the window gives the whole grid's answer. A
    centre or radius that is not finite gets the whole grid."""
    if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(radius)):
        return slice(0, ny), slice(0, nx)
    reach = abs(radius)
    x0 = math.floor((px - reach - sdf.origin[0]) / sdf.cell_m) - 1
    x1 = math.ceil((px + reach - sdf.origin[0]) / sdf.cell_m) + 2
    y0 = math.floor((py - reach - sdf.origin[1]) / sdf.cell_m) - 1
    y1 = math.ceil((py + reach - sdf.origin[1]) / sdf.cell_m) + 2
    return slice(min(max(y0, 0), ny), min(max(y1, 0), ny)), slice(min(max(x0, 0), nx), min(max(x1, 0), nx))


def path_length(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(points, dtype=float), axis=0), axis=1)))


def car_route(scenario: Scenario, car: CarConfig, sdf: SignedDistanceField) -> tuple[tuple[float, float], ...]:
    """The car's own via points, or, if it has none, a route that keeps eps_obs (and
    COMFORT_MARGIN_M more where it can) from obstacles: NoRoute if there is none."""
    if car.route:
        return car.route
    eps_obs = scenario.safety.epsilon_obstacle(car.radius_m)
    return plan_route(sdf, scenario.world.bounds_m, car.start, car.goal, eps_obs, eps_obs + COMFORT_MARGIN_M)


def plan_route(sdf: SignedDistanceField, bounds: tuple[float, float, float, float] | None, start, goal,
               clearance: float, comfort: float, keep_out: Sequence[KeepOut] = ()) -> tuple[tuple[float, float], ...]:
    """Via points (start and goal excluded) from ``start`` to ``goal``; NoRoute if none
    keeps ``clearance`` from obstacles and out of every disc of ``keep_out``. ``bounds``
    (x0, y0, x1, y1) of the search: None, the distance field's own extent."""
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    if bounds is None:
        ny, nx = sdf.values.shape
        bounds = (sdf.origin[0], sdf.origin[1], sdf.origin[0] + (nx - 1) * sdf.cell_m,
                  sdf.origin[1] + (ny - 1) * sdf.cell_m)
    if keep_out:
        sdf = _WithDiscs(sdf, np.array([c for c, _ in keep_out], dtype=float),
                         np.array([r for _, r in keep_out], dtype=float), clearance)
    ends = float(min(sdf.distance(start[None])[0], sdf.distance(goal[None])[0]))
    if segment_clear(sdf, start, goal, min(comfort, ends)):
        return ()
    grid = _Grid(sdf, bounds, clearance, comfort)
    cells = grid.path(start, goal)
    points = np.vstack([start, grid.centres[cells], goal])
    return tuple((round(float(x), 3), round(float(y), 3)) for x, y in _shortcut(sdf, points, comfort)[1:-1])


def _shortcut(sdf: SignedDistanceField, points: np.ndarray, comfort: float) -> np.ndarray:
    distance = sdf.distance(points)
    kept = [0]
    i = 0
    while i < len(points) - 1:
        j = len(points) - 1
        while j > i + 1 and not segment_clear(sdf, points[i], points[j], min(comfort, distance[i], distance[j])):
            j -= 1
        kept.append(j)
        i = j
    return points[kept]


@dataclass(frozen=True)
class _WithDiscs:
    """A distance field with keep-out discs as obstacles (the module's d')."""

    sdf: SignedDistanceField
    centres: np.ndarray
    radii: np.ndarray
    clearance: float

    def distance(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)
        gaps = np.linalg.norm(points[..., None, :] - self.centres, axis=-1) - self.radii + self.clearance
        return np.minimum(self.sdf.distance(points), gaps.min(axis=-1))


class _Grid:
    """The free cells of a map and the edges between neighbouring free cells."""

    def __init__(self, sdf: SignedDistanceField, bounds, clearance: float, comfort: float):
        x0, y0, x1, y1 = bounds
        xs = np.arange(x0 + GRID_M / 2, x1, GRID_M)
        ys = np.arange(y0 + GRID_M / 2, y1, GRID_M)
        gx, gy = np.meshgrid(xs, ys)
        self.shape = gx.shape
        centres = np.stack([gx.ravel(), gy.ravel()], axis=1)
        distance = sdf.distance(centres)
        self.free = distance >= clearance
        self.centres = centres
        index = np.arange(centres.shape[0]).reshape(self.shape)
        rows, cols, weights = [], [], []
        for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
            h, w = self.shape
            a = index[:h - dy, max(0, -dx):w - max(0, dx)].ravel()
            b = index[dy:, max(0, dx):w - max(0, -dx)].ravel()
            ok = self.free[a] & self.free[b]
            a, b = a[ok], b[ok]
            near = np.clip((comfort - np.minimum(distance[a], distance[b])) / comfort, 0.0, 1.0)
            rows.append(a)
            cols.append(b)
            weights.append(GRID_M * np.hypot(dx, dy) * (1.0 + NEAR_WEIGHT * near))
        n = centres.shape[0]
        self.graph = coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(n, n)).tocsr()

    def nearest_free(self, point: np.ndarray) -> int:
        candidates = np.nonzero(self.free)[0]
        if candidates.size == 0:
            raise NoRoute("the map has no free space")
        return int(candidates[np.argmin(np.linalg.norm(self.centres[candidates] - point, axis=1))])

    def path(self, start: np.ndarray, goal: np.ndarray) -> list[int]:
        source, target = self.nearest_free(start), self.nearest_free(goal)
        distance, previous = dijkstra(self.graph, directed=False, indices=source, return_predecessors=True)
        if not np.isfinite(distance[target]):
            raise NoRoute(f"no path from {tuple(start)} to {tuple(goal)} keeps the clearance")
        cells = [target]
        while cells[-1] != source:
            cells.append(int(previous[cells[-1]]))
        return cells[::-1]
