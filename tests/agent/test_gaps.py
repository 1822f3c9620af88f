"""Verification's compiled distances (agent.gaps): numpy's numbers to the last bit."""

import numpy as np
import pytest

from trustfg.agent.gaps import half_steps, peer_gaps
from trustfg.agent.gp import Plan


def numpy_half_steps(points):
    """The numpy form agent.verify had (half the larger step to a neighbour)."""
    if len(points) < 2:
        return np.zeros(len(points))
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    padded = np.concatenate([[step[0]], step, [step[-1]]])
    return 0.5 * np.maximum(padded[:-1], padded[1:])


def numpy_peer_gaps(p, times, peer):
    rel = p - peer.position_at(times)
    return np.linalg.norm(rel, axis=1) - numpy_half_steps(rel)


def random_plan(rng, t0):
    n = int(rng.integers(2, 60))
    scale = rng.uniform(0.01, 5.0)
    return Plan(t0, float(rng.uniform(0.05, 1.0)), rng.normal(size=(n, 2)) * scale,
                rng.normal(size=(n, 2)) * scale)


def test_peer_gaps_are_numpys_to_the_last_bit():
    rng = np.random.default_rng(7)
    for _ in range(2000):
        peer = random_plan(rng, float(rng.uniform(-3.0, 3.0)))
        count = int(rng.integers(1, 500))
        start = float(rng.uniform(-5.0, 5.0))
        times = np.linspace(start, start + float(rng.uniform(0.0, 40.0)), count)  # before, on and past the plan
        p = np.cumsum(rng.normal(size=(count, 2)) * rng.uniform(0.001, 0.5), axis=0)
        assert np.array_equal(peer_gaps(p, times, peer), numpy_peer_gaps(p, times, peer))


def test_half_steps_are_numpys_to_the_last_bit_nan_included():
    rng = np.random.default_rng(8)
    for count in [0, 1, 2, 3, *rng.integers(4, 400, 300)]:
        points = rng.normal(size=(int(count), 2)) * rng.uniform(0.001, 10.0)
        if count > 3 and rng.random() < 0.3:
            points[rng.integers(0, count)] = np.nan
        assert np.array_equal(half_steps(points), numpy_half_steps(points), equal_nan=True)


def test_a_sample_is_charged_half_its_larger_step():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 3.0], [1.0, 3.5]])
    assert half_steps(points).tolist() == [0.5, 1.5, 1.5, 0.25]


def test_a_time_that_is_not_a_number_is_refused():
    peer = Plan(0.0, 1.0, np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="not a number"):
        peer_gaps(np.zeros((2, 2)), np.array([0.0, np.nan]), peer)


def test_positions_and_times_must_pair_up():
    peer = Plan(0.0, 1.0, np.zeros((3, 2)), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="2 positions for 3 times"):
        peer_gaps(np.zeros((2, 2)), np.zeros(3), peer)
