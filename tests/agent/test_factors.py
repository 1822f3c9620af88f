"""Every analytic Jacobian against central differences, at random points and near hinges."""

import functools

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X

from trustfg.agent import factors
from trustfg.agent.gp import interpolation_weights
from trustfg.agent.interval_factors import (
    BatchedIntervals,
    _check_error,
    _chunk_error,
    _consistency_error,
    chunk_bounds,
    chunk_keys,
)

H = 1e-7


def numeric_jacobian(fn, states):
    """d fn / d states for states (I, 4, 2) -> (I, R, 4, 2)."""
    base = fn(states)
    jac = np.zeros(base.shape + (4, 2))
    for j in range(4):
        for d in range(2):
            step = np.zeros_like(states)
            step[:, j, d] = H
            jac[..., j, d] = (fn(states + step) - fn(states - step)) / (2 * H)
    return jac


def make_problem(rng, sdf, n_int, n_peers, dt=0.4, consistency=True, lane=True):
    fractions = factors.check_fractions(4)
    peers = rng.uniform(-1.0, 1.0, (n_int, len(fractions), n_peers, 2))
    return factors.IntervalProblem(
        dt=dt, weights=interpolation_weights(dt, fractions), sdf=sdf, epsilon_obstacle=0.25,
        peer_positions=peers, epsilons=rng.uniform(0.3, 0.9, n_peers), max_speed=0.6,
        consistency_targets=rng.uniform(0.0, 0.5, n_int) if consistency else None,
        lane=np.array([[[-2.0, -0.4], [0.0, -0.4]], [[0.0, -0.4], [0.3, 0.9]]]) if lane else np.zeros((0, 2, 2)),
    )


def states_to_arrays(states):
    """(I, 4, 2) interval states -> consecutive support states for evaluate_intervals."""
    # Use each interval independently: build a 2-state trajectory per interval.
    return states


def interval_residual(problem, states):
    out = []
    for i, s in enumerate(states):
        r, _ = factors.evaluate_intervals(problem, np.stack([s[0], s[2]]), np.stack([s[1], s[3]]),
                                          intervals=np.array([0]), jacobians=False)
        out.append(r[0])
    return np.array(out)


@pytest.mark.parametrize("seed", range(6))
def test_interval_jacobians_match_numerical(intersection_sdf, seed):
    rng = np.random.default_rng(seed)
    n_int = 8
    problem1 = make_problem(rng, intersection_sdf, 1, 3)
    states = np.stack([rng.uniform(-1.2, 1.2, (n_int, 2)), rng.normal(0, 0.5, (n_int, 2)),
                       rng.uniform(-1.2, 1.2, (n_int, 2)), rng.normal(0, 0.5, (n_int, 2))], axis=1)
    # Put some positions right next to peers and obstacles so hinges are active.
    states[0, 0] = problem1.peer_positions[0, 0, 0] + [0.1, 0.05]
    states[1, 0] = [0.55, 0.55]  # 0.25 m from the obstacle corner at (0.8, 0.8)
    analytic = []
    for s in states:
        _, jac = factors.evaluate_intervals(problem1, np.stack([s[0], s[2]]), np.stack([s[1], s[3]]),
                                            intervals=np.array([0]))
        analytic.append(jac[0])
    analytic = np.array(analytic)
    numeric = numeric_jacobian(lambda st: interval_residual(problem1, st), states)
    # Skip the rare rows whose hinge or nearest lane segment switches within +-H.
    mismatch = np.abs(analytic - numeric).max(axis=(2, 3))
    assert np.mean(mismatch < 1e-6) > 0.99, mismatch.max()
    assert np.abs(analytic).sum() > 0  # something was active


def test_near_hinge_both_sides(intersection_sdf):
    """Just inside and just outside the proximity and obstacle thresholds."""
    rng = np.random.default_rng(7)
    problem = make_problem(rng, intersection_sdf, 1, 1, consistency=False, lane=False)
    peer = problem.peer_positions[0, 0, 0]
    eps = problem.epsilons[0]
    for offset in (-1e-4, 1e-4, -1e-3, 1e-3):
        p0 = peer + np.array([eps + offset, 0.0])
        states = np.array([[p0, [0.0, 0.0], p0 + [0.01, 0.0], [0.0, 0.0]]])
        _, jac = factors.evaluate_intervals(problem, states[:, [0, 2]][0], states[:, [1, 3]][0],
                                            intervals=np.array([0]))
        numeric = numeric_jacobian(lambda st: interval_residual(problem, st), states)
        assert np.allclose(jac, numeric, atol=1e-6)


def test_consistency_hinge_is_one_sided(intersection_sdf):
    rng = np.random.default_rng(8)
    problem = make_problem(rng, intersection_sdf, 1, 0, lane=False)
    target = problem.consistency_targets[0]
    calm = np.array([[0, 0], [0.2, 0], [0.08, 0], [0.2 + 0.5 * target * problem.dt, 0]], dtype=float)
    r, _ = factors.evaluate_intervals(problem, calm[[0, 2]], calm[[1, 3]], intervals=np.array([0]))
    assert r[0, -1] == 0.0
    wild = calm.copy()
    wild[3, 0] += 2.0
    r, _ = factors.evaluate_intervals(problem, wild[[0, 2]], wild[[1, 3]], intervals=np.array([0]))
    assert r[0, -1] > 0.0


def test_gtsam_custom_factors_linearise_to_the_numerical_jacobian(intersection_sdf):
    """The factors as GTSAM sees them: batched interval factor and the per-check one."""
    rng = np.random.default_rng(9)
    n = 5
    problem = make_problem(rng, intersection_sdf, n - 1, 2)
    problem = factors.IntervalProblem(**{**problem.__dict__})
    values = gtsam.Values()
    positions = rng.uniform(-1, 1, (n, 2))
    velocities = rng.normal(0, 0.4, (n, 2))
    positions[2] = problem.peer_positions[2, 0, 0] + [0.05, 0.0]
    for i in range(n):
        values.insert(X(i), positions[i])
        values.insert(V(i), velocities[i])
    batch = BatchedIntervals(problem, n, 3)  # chunks of intervals [0, 3) and [3, 4)
    factor_list = [gtsam.CustomFactor(gtsam.noiseModel.Unit.Create((end - first) * problem.rows),
                                      chunk_keys(first, end), functools.partial(_chunk_error, batch, f))
                   for f, (first, end) in enumerate(batch.chunks)]
    check_model = gtsam.noiseModel.Diagonal.Sigmas(np.ones(problem.n_peers + 4))
    factor_list.append(gtsam.CustomFactor(check_model, [X(2), V(2)], functools.partial(_check_error, problem, 2, 0)))
    factor_list.append(gtsam.CustomFactor(gtsam.noiseModel.Unit.Create(1), [V(1), V(2)],
                                          functools.partial(_consistency_error, problem, 1)))
    for factor in factor_list:
        keys = factor.keys()
        jacobian = factor.linearize(values).jacobian()[0]  # whitened = raw, unit sigmas
        for column, key in enumerate(keys):
            for d in range(2):
                plus, minus = gtsam.Values(values), gtsam.Values(values)
                base = values.atVector(key)
                step = np.zeros(2)
                step[d] = H
                plus.update(key, base + step)
                minus.update(key, base - step)
                numeric = (factor.unwhitenedError(plus) - factor.unwhitenedError(minus)) / (2 * H)
                assert np.allclose(jacobian[:, 2 * column + d], numeric, atol=1e-5), (factor, key, d)


def test_chunks_cover_every_interval_once():
    assert chunk_bounds(40, 4) == [(i, i + 4) for i in range(0, 40, 4)]
    assert chunk_bounds(7, 3) == [(0, 3), (3, 6), (6, 7)]
    assert chunk_bounds(2, 5) == [(0, 2)]
    assert chunk_keys(3, 5) == [X(3), V(3), X(4), V(4), X(5), V(5)]


def test_batched_cache_never_serves_stale_slices(intersection_sdf):
    rng = np.random.default_rng(10)
    n = 7
    problem = make_problem(rng, intersection_sdf, n - 1, 1)
    batch = BatchedIntervals(problem, n, 2)
    values = gtsam.Values()
    for i in range(n):
        values.insert(X(i), rng.uniform(-1, 1, 2))
        values.insert(V(i), rng.normal(0, 0.3, 2))
    batch.chunk(1, values, False)
    changed = gtsam.Values(values)
    changed.update(X(2), values.atVector(X(2)) + 0.3)  # a state of chunk 1 (intervals 2, 3)
    pos = gtsam.utilities.extractVectors(changed, "x")
    vel = gtsam.utilities.extractVectors(changed, "v")
    want, jac = factors.evaluate_intervals(problem, pos, vel)
    for f, (first, end) in enumerate(batch.chunks):
        residual, blocks = batch.chunk(f, changed, True)
        assert np.allclose(residual, want[first:end].ravel())
        # Interval l of the chunk: its rows in the blocks of its own two states, zeros elsewhere.
        dense = np.stack(list(blocks)).reshape(2 * (end - first + 1), end - first, problem.rows, 2)
        for local, i in enumerate(range(first, end)):
            for j in range(4):
                assert np.array_equal(dense[2 * local + j, local], jac[i, :, j])
            others = [q for q in range(len(dense)) if not 2 * local <= q < 2 * local + 4]
            assert not dense[others, local].any()
    assert batch.evaluations == 2
