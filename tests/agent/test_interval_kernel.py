"""The compiled interval checks (agent.interval_kernel) against their numpy form:
check_residuals at every GP-interpolated check, chained through the interpolation --
equal to the last bit."""

import numpy as np
import pytest

from trustfg.agent import factors, interval_kernel
from trustfg.agent.config import Obstacle, WorldConfig
from trustfg.agent.gp import interpolation_weights
from trustfg.agent.world import build_sdf


@pytest.fixture(scope="module")
def sdf():
    return build_sdf(WorldConfig(bounds_m=(-2.0, -2.0, 2.0, 2.0), resolution_m=0.02, obstacles=(
        Obstacle("rect", (-0.3, -0.3), (0.3, 0.2)),
        Obstacle(kind="polygon", points=((0.8, 0.8), (1.5, 0.9), (1.0, 1.6))),
    )))


def reference(problem, positions, velocities, intervals):
    """The rows and Jacobian blocks (I, R, 4, 2) with numpy, one check at a time."""
    support = np.concatenate([positions, velocities], axis=1)
    states = np.concatenate([support[intervals], support[intervals + 1]], axis=1).reshape(-1, 4, 2)
    k = problem.n_checks
    pv = problem.weights.reshape(2 * k, 4) @ states
    p, v = pv[:, 0::2], pv[:, 1::2]
    r, d_dp, d_dv = factors.check_residuals(p, v, problem.peer_positions[intervals], problem.epsilons, problem.sdf,
                                            problem.epsilon_obstacle, problem.max_speed, problem.lane)
    per_check = r.shape[-1]
    residual = np.zeros((len(states), problem.rows))
    jac = np.zeros((len(states), problem.rows, 4, 2))
    residual[:, :k * per_check] = r.reshape(len(states), -1)
    w_pos, w_vel = problem.weights[:, 0], problem.weights[:, 1]  # (K, 4)
    chained = d_dp[:, :, :, None, :] * w_pos[None, :, None, :, None] + d_dv[:, :, :, None, :] * w_vel[None, :, None, :, None]
    jac[:, :k * per_check] = chained.reshape(len(states), k * per_check, 4, 2)
    if problem.consistency_targets is not None:
        a = (states[:, 3] - states[:, 1]) / problem.dt
        root = np.sqrt((a * a).sum(axis=1) + factors.SMOOTH_ACCEL_DELTA**2)
        excess = root - factors.SMOOTH_ACCEL_DELTA - problem.consistency_targets[intervals]
        residual[:, -1] = np.maximum(excess, 0.0)
        da = a * ((excess > 0.0) / root / problem.dt)[:, None]
        jac[:, -1, 1], jac[:, -1, 3] = -da, da
    return residual, jac


def problem_and_states(rng, sdf, n, n_peers, consistency, segments):
    dt = 0.35
    fractions = factors.check_fractions(4)
    lane = np.zeros((0, 2, 2))
    if segments:
        corners = rng.uniform(-1.8, 1.8, (segments + 1, 2))
        lane = np.stack([corners[:-1], corners[1:]], axis=1)
    problem = factors.IntervalProblem(
        dt=dt, weights=interpolation_weights(dt, fractions), sdf=sdf, epsilon_obstacle=0.25,
        peer_positions=rng.uniform(-1.5, 1.5, (n - 1, len(fractions), n_peers, 2)),
        epsilons=rng.uniform(0.3, 0.9, n_peers), max_speed=0.6,
        consistency_targets=rng.uniform(0.0, 0.5, n - 1) if consistency else None, lane=lane)
    # near obstacles and peers, some off the grid, some fast: every hinge both ways
    positions = rng.uniform(-2.4, 2.4, (n, 2))
    velocities = rng.normal(0.0, 0.6, (n, 2))
    return problem, positions, velocities


@pytest.mark.parametrize("seed", range(12))
def test_rows_and_jacobians_are_those_of_the_numpy_form(sdf, seed):
    rng = np.random.default_rng(seed)
    n_peers, consistency, segments = seed % 4, seed % 3 != 0, seed % 3
    problem, positions, velocities = problem_and_states(rng, sdf, 41, n_peers, consistency, segments)
    everything = np.arange(40)
    residual, jac = factors.evaluate_intervals(problem, positions, velocities)
    want_residual, want_jac = reference(problem, positions, velocities, everything)
    assert residual.shape == want_residual.shape and jac.shape == want_jac.shape
    assert np.abs(residual).max() > 0 and np.abs(jac).max() > 0
    # the same numbers, bit for bit: the planner's results do not move (the bank repeats)
    np.testing.assert_array_equal(residual, want_residual)
    np.testing.assert_array_equal(jac, want_jac)
    # every kind of row was active somewhere (a check that does not test a hinge proves nothing)
    per_check = n_peers + 2 + (2 if segments else 0)
    kinds = residual[:, :5 * per_check].reshape(40, 5, per_check)
    assert (kinds[..., 0] > 0).any() and (kinds[..., n_peers + 1] > 0).any()
    assert all((kinds[..., 1 + m] > 0).any() for m in range(n_peers))


def test_a_subset_of_intervals_and_rows_only(sdf):
    rng = np.random.default_rng(3)
    problem, positions, velocities = problem_and_states(rng, sdf, 21, 2, True, 2)
    chosen = np.array([0, 7, 19, 7])
    residual, jac = factors.evaluate_intervals(problem, positions, velocities, intervals=chosen, jacobians=False)
    assert jac is None
    np.testing.assert_array_equal(residual, factors.evaluate_intervals(problem, positions, velocities)[0][chosen])


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_states_that_are_not_finite_are_refused(sdf, bad):
    """The compiled loop does not check its indices: a NaN must not reach the grid."""
    rng = np.random.default_rng(4)
    problem, positions, velocities = problem_and_states(rng, sdf, 6, 1, True, 1)
    positions[3, 1] = bad
    with pytest.raises(ValueError, match="not finite"):
        factors.evaluate_intervals(problem, positions, velocities)


def test_one_compiled_signature_whatever_the_layout_of_the_states(sdf):
    """GTSAM hands the states over in column order: without the wrapper's conversion a
    process would compile the loop a second time in its first plan, long enough for a car
    process to let its command loop's permit lapse."""
    rng = np.random.default_rng(5)
    problem, positions, velocities = problem_and_states(rng, sdf, 11, 2, True, 1)
    for order in ("C", "F"):
        factors.evaluate_intervals(problem, np.asarray(positions, order=order), np.asarray(velocities, order=order))
        factors.evaluate_intervals(problem, np.asarray(positions, order=order), np.asarray(velocities, order=order),
                                   intervals=np.arange(10)[::2], jacobians=False)
    assert len(interval_kernel._evaluate.signatures) == 1
