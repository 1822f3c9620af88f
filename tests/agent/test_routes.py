"""Routes of generated scenes keep their clearance from obstacles, or there is none."""

import math

import numpy as np
import pytest

from trustfg.agent.config import Obstacle, WorldConfig
from trustfg.agent.routes import NoRoute, free_cells, plan_route, segment_clear
from trustfg.agent.world import build_sdf

BOUNDS = (-2.0, -1.5, 2.0, 1.5)
CLEARANCE, COMFORT = 0.25, 0.4


def _sdf(*obstacles):
    return build_sdf(WorldConfig(bounds_m=BOUNDS, resolution_m=0.02, obstacles=tuple(obstacles)))


def test_a_clear_straight_line_needs_no_via_points():
    assert plan_route(_sdf(), BOUNDS, (-1.5, 0.0), (1.5, 0.0), CLEARANCE, COMFORT) == ()


def test_a_route_around_a_wall_keeps_the_clearance_the_straight_line_breaks():
    wall = Obstacle(kind="rect", min=(-0.1, -1.5), max=(0.1, 0.7))  # a gap of 0.8 m at the top
    sdf = _sdf(wall)
    start, goal = np.array([-1.5, -1.0]), np.array([1.5, -1.0])
    assert not segment_clear(sdf, start, goal, CLEARANCE)
    route = plan_route(sdf, BOUNDS, start, goal, CLEARANCE, COMFORT)
    points = np.array([start, *route, goal])
    assert len(route) >= 1
    assert all(segment_clear(sdf, a, b, CLEARANCE) for a, b in zip(points[:-1], points[1:]))
    assert all(p[1] > 0.7 for p in route[:1])  # it goes through the gap


def test_no_route_through_a_wall_without_a_gap():
    sdf = _sdf(Obstacle(kind="rect", min=(-0.1, -1.5), max=(0.1, 1.5)))
    with pytest.raises(NoRoute):
        plan_route(sdf, BOUNDS, (-1.5, 0.0), (1.5, 0.0), CLEARANCE, COMFORT)


def _free_cells_whole_grid(sdf, clearance, keep_out):
    """free_cells as the formula reads, every disc tested on every cell."""
    ny, nx = sdf.values.shape
    xs = sdf.origin[0] + np.arange(nx) * sdf.cell_m
    ys = sdf.origin[1] + np.arange(ny) * sdf.cell_m
    free = sdf.values >= clearance
    for (px, py), radius in keep_out:
        free &= (xs[None, :] - px) ** 2 + (ys[:, None] - py) ** 2 >= radius * radius
    return free


def test_free_cells_tests_each_disc_on_its_window_with_the_whole_grids_answer():
    sdf = _sdf(Obstacle(kind="rect", min=(-0.2, -0.5), max=(0.2, 0.5)))
    x0, y0 = sdf.origin
    x1, y1 = x0 + sdf.values.shape[1] * sdf.cell_m, y0 + sdf.values.shape[0] * sdf.cell_m
    rng = np.random.default_rng(7)
    for trial in range(300):
        keep_out = []
        for _ in range(rng.integers(0, 6)):
            # centres inside, on the rim and outside the grid; radii from a cell to the room
            centre = (float(rng.uniform(x0 - 1.0, x1 + 1.0)), float(rng.uniform(y0 - 1.0, y1 + 1.0)))
            radius = float(rng.choice([rng.uniform(0.0, 0.1), rng.uniform(0.1, 1.0), rng.uniform(1.0, 6.0)]))
            keep_out.append((centre, -radius if trial % 7 == 0 else radius))
        expected = _free_cells_whole_grid(sdf, 0.2, keep_out)
        assert np.array_equal(free_cells(sdf, 0.2, keep_out), expected), keep_out
    # a disc exactly on cell centres, and what is not finite (the whole grid, as the formula)
    on_grid = [((x0 + 10 * sdf.cell_m, y0 + 12 * sdf.cell_m), 5 * sdf.cell_m)]
    assert np.array_equal(free_cells(sdf, 0.2, on_grid), _free_cells_whole_grid(sdf, 0.2, on_grid))
    for odd in ([((math.nan, 0.0), 0.5)], [((0.0, 0.0), math.inf)], [((math.inf, 0.0), 0.5)]):
        assert np.array_equal(free_cells(sdf, 0.2, odd), _free_cells_whole_grid(sdf, 0.2, odd))
