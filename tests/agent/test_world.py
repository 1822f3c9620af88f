import numpy as np
import pytest

from trustfg.agent.config import Obstacle, WorldConfig
from trustfg.agent.world import build_sdf, exact_distance


@pytest.fixture(scope="module")
def world():
    return WorldConfig(bounds_m=(-2.5, -2.5, 2.5, 2.5), resolution_m=0.01, obstacles=(
        Obstacle("rect", (0.8, 0.8), (2.5, 2.5)),
        Obstacle("rect", (-2.5, -2.5), (-0.8, -0.8)),
        Obstacle("rect", (-0.3, 0.5), (0.2, 0.9)),
    ))


def test_sdf_matches_analytic_distance(world):
    sdf = build_sdf(world)
    rng = np.random.default_rng(1)
    points = rng.uniform(-2.45, 2.45, (2000, 2))
    got = sdf.distance(points)
    want = np.array([exact_distance(world, tuple(p)) for p in points])
    free = want >= 0
    assert free.sum() > 1000 and (~free).sum() > 200
    # In free space (what the planner's hinge sees): within the grid's discretisation.
    assert np.max(np.abs(got[free] - want[free])) < 1.5 * world.resolution_m
    # Inside obstacles the analytic formula ignores touching walls and blocks, so only
    # the sign is compared there.
    inside = want < -2 * world.resolution_m
    assert np.all(got[inside] < 0)


def test_sdf_gradient_is_the_derivative_of_the_lookup(world):
    sdf = build_sdf(world)
    rng = np.random.default_rng(2)
    points = rng.uniform(-2.4, 2.4, (300, 2))
    _, grad = sdf.distance_and_gradient(points)
    h = 1e-6
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = h
        numeric = (sdf.distance(points + step) - sdf.distance(points - step)) / (2 * h)
        # Bilinear lookup: exact except on cell borders, which random points avoid.
        assert np.median(np.abs(numeric - grad[:, axis])) < 1e-6
        assert np.mean(np.abs(numeric - grad[:, axis]) < 1e-4) > 0.98


def test_sdf_gradient_points_away_from_obstacles(world):
    sdf = build_sdf(world)
    # Right of the small block, below the big one: the gradient points +x.
    _, grad = sdf.distance_and_gradient(np.array([[0.5, 0.7]]))
    assert grad[0, 0] > 0.9 and abs(grad[0, 1]) < 0.2
    # Outside the arena counts as obstacle.
    assert sdf.distance(np.array([[3.0, 0.0]]))[0] < 0


def test_one_point_gives_the_numbers_of_many_points():
    """A single point takes a plain-float path; it must give the very numbers (and shapes)
    the array path gives, off the grid too (the bank's runs repeat exactly from the seed)."""
    world = WorldConfig(bounds_m=(-2.0, -2.0, 2.0, 2.0), resolution_m=0.02,
                        obstacles=(Obstacle(kind="polygon", points=((0.3, -0.6), (0.8, 0.1), (-0.1, 0.3))),))
    sdf = build_sdf(world)
    points = np.random.default_rng(5).uniform(-3.0, 3.0, size=(2000, 2))
    distance, gradient = sdf.distance_and_gradient(points)
    for k, point in enumerate(points):
        d, g = sdf.distance_and_gradient(point)
        assert d.shape == () and g.shape == (2,)
        assert d == distance[k] and np.array_equal(g, gradient[k])


def test_distance_alone_gives_the_numbers_of_distance_and_gradient(world):
    """``distance`` skips the gradient; its numbers must be those of distance_and_gradient,
    on the grid, off it and in every shape (the bank's runs repeat exactly from the seed)."""
    sdf = build_sdf(world)
    rng = np.random.default_rng(6)
    for shape in [(2000, 2), (40, 5, 2), (1, 2), (3, 1, 2)]:
        points = rng.uniform(-3.5, 3.5, shape)
        alone = sdf.distance(points)
        assert alone.shape == shape[:-1]
        assert np.array_equal(alone, sdf.distance_and_gradient(points)[0])


@pytest.mark.parametrize("point", [(np.nan, 0.0), (0.0, np.nan), (np.nan, np.nan)])
def test_a_point_that_is_not_a_number_is_refused(world, point):
    """Not a wrong distance: with one coordinate NaN a flat index can land on a real cell."""
    sdf = build_sdf(world)
    for points in (np.array(point), np.array([[0.1, 0.2], point])):
        with pytest.raises(ValueError, match="not a number"):
            sdf.distance(points)
        with pytest.raises(ValueError, match="not a number"):
            sdf.distance_and_gradient(points)
