"""The car-like rows of the factor graph: every Jacobian against central differences, and
what the rows ask of a plan (agent.heading_factors)."""

import functools
import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X, Y

from trustfg.agent.heading_factors import _chunk_error, chunk_keys, heading_rows, row_sigmas

H = 1e-7


def rows_of(states: np.ndarray, dt: float, curvature: float, last: bool) -> np.ndarray:
    """heading_rows of states (k, 5): p, v, theta per state."""
    return heading_rows(states[:, 0:2], states[:, 2:4], states[:, 4], dt, curvature, last)[0]


def numeric(states: np.ndarray, dt: float, curvature: float, last: bool) -> np.ndarray:
    base = rows_of(states, dt, curvature, last)
    jac = np.zeros(base.shape + states.shape)
    for j in range(states.shape[0]):
        for d in range(states.shape[1]):
            step = np.zeros_like(states)
            step[j, d] = H
            jac[:, j, d] = (rows_of(states + step, dt, curvature, last)
                            - rows_of(states - step, dt, curvature, last)) / (2 * H)
    return jac


def analytic(states: np.ndarray, dt: float, curvature: float, last: bool) -> np.ndarray:
    _, d_p, d_v, d_theta = heading_rows(states[:, 0:2], states[:, 2:4], states[:, 4], dt, curvature, last)
    return np.concatenate([d_p, d_v, d_theta[..., None]], axis=2)


def random_states(rng: np.random.Generator, k: int) -> np.ndarray:
    """k states that turn, reverse and slide a little each, so every hinge is active somewhere."""
    theta = np.cumsum(rng.uniform(-1.2, 1.2, k))
    speed = rng.uniform(-0.2, 0.6, k)
    heading = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    v = speed[:, None] * heading + rng.normal(0.0, 0.05, (k, 2))
    steps = rng.uniform(-0.05, 0.25, k - 1)[:, None] * heading[:-1] + rng.normal(0.0, 0.03, (k - 1, 2))
    p = np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])
    return np.column_stack([p, v, theta])


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("last", [False, True])
def test_jacobians_match_numerical(seed, last):
    rng = np.random.default_rng(seed)
    states = random_states(rng, 6)
    dt, curvature = 0.3, 1.0 / 0.345
    got, want = analytic(states, dt, curvature, last), numeric(states, dt, curvature, last)
    # Rows whose hinge switches within +-H are rare; none of these seeds has one.
    assert np.allclose(got, want, atol=1e-6), np.abs(got - want).max()
    residual = rows_of(states, dt, curvature, last)
    assert np.count_nonzero(residual) > len(residual) // 3  # the hinges were tried active, not only flat


def test_jacobians_at_the_hinges_both_sides():
    """Just inside and just outside the turning limit and the no-reversing hinge."""
    dt, curvature = 0.5, 1.0 / 0.3
    for offset in (-1e-4, 1e-4, -1e-3, 1e-3):
        chord = 0.2
        turn = curvature * chord + offset  # the turn the chord allows, and a hair more or less
        states = np.array([[0.0, 0.0, 0.4, 0.0, 0.0],
                           [chord * math.cos(turn / 2), chord * math.sin(turn / 2), 0.4, 0.0, turn]])
        assert np.allclose(analytic(states, dt, curvature, True), numeric(states, dt, curvature, True), atol=1e-6)
        # (a turn of its own: |turn| has no derivative at 0, where reversing makes the row active)
        backwards = np.array([[0.0, 0.0, offset, 0.0, 0.0], [offset, 0.0, offset, 0.0, 0.05]])
        assert np.allclose(analytic(backwards, dt, curvature, True), numeric(backwards, dt, curvature, True),
                           atol=1e-6)


def test_an_arc_of_the_radius_passes_and_a_tighter_one_does_not():
    """States on a circle of radius R (velocities along it, headings its tangents) leave
    every row zero at curvature 1/R (the chord understates the arc, so with a hair of
    slack); a circle of R/2 breaks the turning rows, a slide across the heading the
    sideways rows, and driving it backwards the backwards rows."""
    radius, dt, speed = 0.3, 0.25, 0.4

    def circle(r: float, direction: float = 1.0) -> np.ndarray:
        theta = np.arange(8) * speed * dt / r
        p = r * np.stack([np.sin(theta), 1 - np.cos(theta)], axis=1)
        v = direction * speed * np.stack([np.cos(theta), np.sin(theta)], axis=1)
        return np.column_stack([p, v, theta])

    fine = rows_of(circle(radius), dt, 1.0 / (radius * 0.99), True)
    assert np.allclose(fine, 0.0, atol=1e-12)
    tight = rows_of(circle(radius / 2), dt, 1.0 / radius, True)
    turning = tight[2 * 8:].reshape(7, 3)[:, 2]
    assert np.all(turning > 0.3)
    slid = circle(radius)
    slid[:, 4] += 0.3  # the wheels point 0.3 rad off the way the car goes
    assert np.all(np.abs(rows_of(slid, dt, 1.0 / radius, True)[0:16:2]) > 0.1)
    backwards = rows_of(circle(radius, -1.0), dt, 1.0 / radius, True)
    assert np.all(backwards[1:16:2] > 0.3)


def test_standing_still_the_heading_stays():
    """A plan that stands between two states may not turn its heading there: the turn is
    all excess, whatever the sign."""
    for turn in (0.5, -0.5):
        states = np.array([[0.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0, turn]])
        residual = rows_of(states, 0.5, 1.0 / 0.3, True)
        assert residual[-1] == pytest.approx(abs(turn))


def test_the_gtsam_factor_linearises_to_the_numerical_jacobian():
    rng = np.random.default_rng(3)
    n, dt, curvature = 6, 0.3, 1.0 / 0.345
    states = random_states(rng, n)
    values = gtsam.Values()
    for i in range(n):
        values.insert(X(i), states[i, 0:2])
        values.insert(V(i), states[i, 2:4])
        values.insert(Y(i), states[i, 4:5])
    for first, end in [(0, 3), (3, 5)]:
        last = end == n - 1
        rows = len(row_sigmas(end - first + (1 if last else 0), end - first, dt, 1.0, 1.0))
        factor = gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(rows), chunk_keys(first, end),
                                    functools.partial(_chunk_error, dt, curvature, last))
        jacobian = factor.linearize(values).jacobian()[0]
        column = 0
        for key in factor.keys():
            base = values.atVector(key)
            for d in range(len(base)):
                plus, minus = gtsam.Values(values), gtsam.Values(values)
                step = np.zeros(len(base))
                step[d] = H
                plus.update(key, base + step)
                minus.update(key, base - step)
                want = (factor.unwhitenedError(plus) - factor.unwhitenedError(minus)) / (2 * H)
                assert np.allclose(jacobian[:, column], want, atol=1e-5), (key, d)
                column += 1
        assert column == 5 * (end - first + 1)
