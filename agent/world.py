"""The map as a signed distance field (paper eqs. (5)-(6)).

Obstacles (rectangles, polygons) and the arena's walls are rasterised on a grid; scipy's
Euclidean distance transform gives, for every cell centre, the distance to the nearest
obstacle cell (outside) or free cell (inside). The signed distance is

    d(z) = dist_to_obstacle(z) - dist_to_free(z)      (> 0 in free space, < 0 inside)

with a half-cell correction so that the zero level lies on the obstacle boundary.
Lookups are bilinear, so d is continuous and its gradient is the exact derivative of the
interpolant (piecewise constant along each axis), which is what the hinge factors'
Jacobians need.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import Obstacle, WorldConfig


@dataclass(frozen=True)
class SignedDistanceField:
    """A signed distance grid; ``values[iy, ix]`` is d at (x0 + ix*cell, y0 + iy*cell)."""

    origin: tuple[float, float]
    cell_m: float
    values: np.ndarray

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance at points of shape (..., 2): distance_and_gradient's d, without
        the gradient (the same operations, so the same numbers)."""
        points = np.asarray(points, dtype=float)
        if points.shape == (2,) and math.isfinite(points[0]) and math.isfinite(points[1]):
            return self._at_point(*points.tolist())[0]
        fx, fy, d00, d01, d10, d11 = self._corners(points)
        bottom = d00 + fx * (d01 - d00)
        return bottom + fy * (d10 + fx * (d11 - d10) - bottom)

    def distance_and_gradient(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear d(z) and its gradient at points (..., 2) -> (...,), (..., 2).

        Points off the grid are clamped to its border cells, whose values are inside the
        walls (negative), so leaving the arena is always costly.
        """
        points = np.asarray(points, dtype=float)
        if points.shape == (2,) and math.isfinite(points[0]) and math.isfinite(points[1]):
            return self._at_point(*points.tolist())
        fx, fy, d00, d01, d10, d11 = self._corners(points)
        # d = (1-fy)[(1-fx) d00 + fx d01] + fy[(1-fx) d10 + fx d11]
        bottom = d00 + fx * (d01 - d00)
        top = d10 + fx * (d11 - d10)
        dist = bottom + fy * (top - bottom)
        grad = np.empty(dist.shape + (2,))
        np.divide((1 - fy) * (d01 - d00) + fy * (d11 - d10), self.cell_m, out=grad[..., 0])
        np.divide(top - bottom, self.cell_m, out=grad[..., 1])
        return dist, grad

    def _corners(self, points: np.ndarray) -> tuple[np.ndarray, ...]:
        """The fractions (fx, fy) of each point within its cell and d at the cell's four
        corners, d00 (its own), d01 (+x), d10 (+y), d11."""
        ny, nx = self.values.shape
        grid = (points - self.origin) / self.cell_m
        np.minimum(np.maximum(grid, 0.0, out=grid), (nx - 1.000001, ny - 1.000001), out=grid)  # np.clip is slower
        if np.isnan(grid).any():  # (infinities are clamped to the border above)
            raise ValueError("signed distance asked at a point that is not a number")
        gx, gy = grid[..., 0], grid[..., 1]
        ix = gx.astype(np.intp)
        iy = gy.astype(np.intp)
        flat = self.values.ravel()  # a view; one flat index per corner is cheaper than [iy, ix]
        cell = iy * nx + ix
        return (gx - ix, gy - iy, flat.take(cell), flat.take(cell + 1), flat.take(cell + nx),
                flat.take(cell + nx + 1))

    def _at_point(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray]:
        """distance_and_gradient at one point, in plain floats: the same operations in the
        same order, so the same numbers (the guard asks for one point at every tick)."""
        ny, nx = self.values.shape
        gx = min(max((x - self.origin[0]) / self.cell_m, 0.0), nx - 1.000001)
        gy = min(max((y - self.origin[1]) / self.cell_m, 0.0), ny - 1.000001)
        ix, iy = int(gx), int(gy)
        fx, fy = gx - ix, gy - iy
        (d00, d01), (d10, d11) = self.values[iy:iy + 2, ix:ix + 2].tolist()
        bottom = d00 + fx * (d01 - d00)
        top = d10 + fx * (d11 - d10)
        return (np.array(bottom + fy * (top - bottom)),
                np.array([((1 - fy) * (d01 - d00) + fy * (d11 - d10)) / self.cell_m, (top - bottom) / self.cell_m]))


def obstacle_mask(world: WorldConfig) -> tuple[np.ndarray, tuple[float, float]]:
    """Occupancy grid (True = obstacle) of cell centres, walls included, and its origin.

    The grid extends two cells beyond the arena so the walls are rasterised too.
    """
    x0, y0, x1, y1 = world.bounds_m
    cell = world.resolution_m
    pad = 2 * cell
    xs = np.arange(x0 - pad, x1 + pad + cell / 2, cell)
    ys = np.arange(y0 - pad, y1 + pad + cell / 2, cell)
    gx, gy = np.meshgrid(xs, ys)
    mask = (gx < x0) | (gx > x1) | (gy < y0) | (gy > y1)
    for obstacle in world.obstacles:
        mask |= _inside(obstacle, gx, gy)
    return mask, (float(xs[0]), float(ys[0]))


def build_sdf(world: WorldConfig) -> SignedDistanceField:
    mask, origin = obstacle_mask(world)
    cell = world.resolution_m
    from scipy import ndimage  # here: the command loop (fleet.car.velocity_loop) reads a field, never builds one

    outside = ndimage.distance_transform_edt(~mask) * cell  # free cells: distance to obstacle
    inside = ndimage.distance_transform_edt(mask) * cell  # obstacle cells: distance to free
    # The transform measures centre to centre; the boundary lies half a cell in between.
    values = np.where(mask, -(inside - 0.5 * cell), outside - 0.5 * cell)
    return SignedDistanceField(origin=origin, cell_m=cell, values=values)


def _inside(obstacle: Obstacle, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    if obstacle.kind == "rect":
        (ax, ay), (bx, by) = obstacle.min, obstacle.max
        return (gx >= ax) & (gx <= bx) & (gy >= ay) & (gy <= by)
    from matplotlib.path import Path as PolygonPath

    polygon = PolygonPath(np.asarray(obstacle.points, dtype=float))
    points = np.stack([gx.ravel(), gy.ravel()], axis=1)
    return polygon.contains_points(points).reshape(gx.shape)


def exact_distance(world: WorldConfig, point: tuple[float, float]) -> float:
    """Analytic signed distance for rectangles and walls (tests and metrics).

    Positive outside every obstacle; only rectangles are supported analytically.
    """
    x, y = point
    x0, y0, x1, y1 = world.bounds_m
    wall = min(x - x0, x1 - x, y - y0, y1 - y)
    best = wall
    for obstacle in world.obstacles:
        if obstacle.kind != "rect":
            raise ValueError("exact_distance supports rectangles only")
        best = min(best, _rect_signed_distance(obstacle, x, y))
    return best


def _rect_signed_distance(rect: Obstacle, x: float, y: float) -> float:
    (ax, ay), (bx, by) = rect.min, rect.max
    dx = max(ax - x, 0.0, x - bx)
    dy = max(ay - y, 0.0, y - by)
    if dx > 0 or dy > 0:
        return float(np.hypot(dx, dy))
    return -min(x - ax, bx - x, y - ay, by - y)
