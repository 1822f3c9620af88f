import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X

from trustfg.agent.gp import FEW_TIMES, Plan, interpolation_matrices, interpolation_weights


def random_plan(rng, n=6, t0=1.0, dt=0.7):
    return Plan(t0, dt, rng.normal(size=(n, 2)), rng.normal(size=(n, 2)))


def test_lambda_psi_reproduce_the_endpoints():
    lam, psi = interpolation_matrices(0.5, 0.0)
    assert np.allclose(lam, np.eye(2)) and np.allclose(psi, 0)
    lam, psi = interpolation_matrices(0.5, 0.5)
    assert np.allclose(lam, 0) and np.allclose(psi, np.eye(2))


def test_plan_interpolation_is_the_wnoa_posterior_mean():
    rng = np.random.default_rng(0)
    plan = random_plan(rng)
    for tau in rng.uniform(0.0, plan.dt, 20):
        lam, psi = interpolation_matrices(plan.dt, tau)
        i = 2
        x = lam @ np.stack([plan.positions[i], plan.velocities[i]]) + psi @ np.stack(
            [plan.positions[i + 1], plan.velocities[i + 1]])
        (p,), (v,) = plan.state_at(plan.t0 + (i * plan.dt) + tau)
        assert np.allclose(x[0], p, atol=1e-12) and np.allclose(x[1], v, atol=1e-12)


def test_interpolation_agrees_with_gtsam():
    """Our Lambda/Psi against GTSAM's own WNOA interpolator (updateInterpValuesPoint2)."""
    rng = np.random.default_rng(3)
    dt, qc = 0.4, np.array([0.7, 0.7])
    values = gtsam.Values()
    graph = gtsam.NonlinearFactorGraph()
    estimated = {gtsam.StateData(X(0), V(0), 0.0), gtsam.StateData(X(2), V(2), dt)}
    p0, v0, p2, v2 = rng.normal(size=(4, 2))
    for key, value in ((X(0), p0), (V(0), v0), (X(2), p2), (V(2), v2)):
        values.insert(key, value)
    graph.add(gtsam.WnoaMotionFactorPoint2(*sorted(estimated, key=lambda s: s.time), qc))
    tau = 0.13
    interp = {gtsam.StateData(X(1), V(1), tau)}
    result = gtsam.updateInterpValuesPoint2(graph, values, estimated, interp, qc)
    plan = Plan(0.0, dt, np.stack([p0, p2]), np.stack([v0, v2]))
    (p,), (v,) = plan.state_at(tau)
    assert np.allclose(result.atPoint2(X(1)), p, atol=1e-9)
    assert np.allclose(result.atPoint2(V(1)), v, atol=1e-9)  # stored as a fixed-size Vector2


def test_weights_match_matrices():
    w = interpolation_weights(0.5, np.array([0.0, 0.25, 0.6]))
    lam, psi = interpolation_matrices(0.5, 0.125)
    assert np.allclose(w[1, :, :2], lam) and np.allclose(w[1, :, 2:], psi)


def test_acceleration_is_the_derivative_of_velocity():
    rng = np.random.default_rng(1)
    plan = random_plan(rng)
    for t in rng.uniform(plan.t0 + 0.01, plan.t_end - 0.01, 20):
        h = 1e-6
        numeric = (plan.state_at(t + h)[1] - plan.state_at(t - h)[1]) / (2 * h)
        assert np.allclose(plan.acceleration_at(t), numeric, atol=1e-5)


def test_plan_rests_outside_its_span():
    rng = np.random.default_rng(2)
    plan = random_plan(rng)
    (p,), (v,) = plan.state_at(plan.t_end + 5.0)
    assert np.allclose(p, plan.positions[-1]) and np.allclose(v, 0.0)
    (p,), _ = plan.state_at(plan.t0 - 5.0)
    assert np.allclose(p, plan.positions[0])


@pytest.mark.parametrize("t0, dt, n", [(0.3, 0.1, 30), (2.0, 0.9, 5)])
def test_resampling_preserves_the_trajectory(t0, dt, n):
    rng = np.random.default_rng(4)
    plan = random_plan(rng, n=8, t0=0.0, dt=0.5)
    again = plan.resampled(t0, dt, n)
    inside = again.times()[again.times() <= plan.t_end]
    assert np.allclose(again.position_at(inside), plan.position_at(inside))


def test_one_time_gives_the_numbers_of_many_times():
    """state_at for up to FEW_TIMES times takes a plain-float path; it must give the very
    numbers the array path gives (the bank's runs repeat exactly from the seed)."""
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(2, 45))
        plan = Plan(float(rng.normal() * 5), float(rng.uniform(0.05, 1.0)), rng.normal(size=(n, 2)),
                    rng.normal(size=(n, 2)))
        times = [*rng.uniform(plan.t0 - 1.0, plan.t_end + 1.0, 5), plan.t0, plan.t_end, plan.t0 + 2 * plan.dt]
        many = plan.state_at(np.array(times + [plan.t0 + 0.5 * plan.dt]))
        for k, t in enumerate(times):
            for one in (plan.state_at(t), plan.state_at(np.array([t]))):
                assert one[0].shape == one[1].shape == (1, 2)
                assert np.array_equal(one[0][0], many[0][k]) and np.array_equal(one[1][0], many[1][k])
        few = plan.state_at(np.array(times[:FEW_TIMES]))
        assert np.array_equal(few[0], many[0][:FEW_TIMES]) and np.array_equal(few[1], many[1][:FEW_TIMES])


def numpy_state_at(plan, t):
    """state_at in numpy operations: the reference the compiled loop (agent.interpolate)
    must match to the last bit."""
    s = (t - plan.t0) / plan.dt
    index = np.minimum(np.maximum(np.floor(s), 0.0), plan.n - 2).astype(np.intp)
    u = np.minimum(np.maximum(s - index, 0.0), 1.0)[:, None]
    dt, u2 = plan.dt, u * u
    u3 = u2 * u
    p0, p1 = plan.positions[index], plan.positions[index + 1]
    v0, v1 = plan.velocities[index], plan.velocities[index + 1]
    pos = p0 + (3 * u2 - 2 * u3) * (p1 - p0) + (u3 - 2 * u2 + u) * dt * v0 + (u3 - u2) * dt * v1
    vel = (6 * (u - u2) / dt) * (p1 - p0) + (3 * u2 - 4 * u + 1) * v0 + (3 * u2 - 2 * u) * v1
    pos[s <= 0.0], vel[s <= 0.0] = plan.positions[0], plan.velocities[0]
    pos[s >= plan.n - 1], vel[s >= plan.n - 1] = plan.positions[-1], 0.0
    acc = ((12 * u - 6) * (p0 - p1) / dt**2 + (6 * u - 4) * v0 / dt + (6 * u - 2) * v1 / dt)
    return pos, vel, np.where(((s < 0.0) | (s > plan.n - 1))[:, None], 0.0, acc)


def test_many_times_give_the_numbers_of_the_numpy_form():
    """Many times go to the compiled loop (agent.interpolate): the numbers of the numpy
    form, bit for bit, before, inside and after the plan, infinities too; and one time at
    a time (plain floats) the same again."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        n = int(rng.integers(2, 45))
        plan = Plan(float(rng.normal() * 5), float(rng.uniform(0.05, 1.0)), rng.normal(size=(n, 2)),
                    rng.normal(size=(n, 2)))
        times = np.concatenate([rng.uniform(plan.t0 - 1.0, plan.t_end + 1.0, 40), plan.times(),
                                [plan.t0, plan.t_end, -np.inf, np.inf]])
        pos, vel, acc = numpy_state_at(plan, times)
        got_pos, got_vel = plan.state_at(times)
        assert np.array_equal(got_pos, pos) and np.array_equal(got_vel, vel)
        assert np.array_equal(plan.acceleration_at(times), acc)
        for k in rng.choice(len(times), 5):
            assert np.array_equal(plan.acceleration_at(times[k]), acc[k:k + 1])


def test_a_time_that_is_not_a_number_is_refused():
    plan = Plan(0.0, 0.5, np.zeros((4, 2)), np.ones((4, 2)))
    for times in (np.array([np.nan]), np.array([0.1, np.nan, 0.2, 0.3, 0.4])):
        with pytest.raises(ValueError, match="not a number"):
            plan.state_at(times)
        with pytest.raises(ValueError, match="not a number"):
            plan.acceleration_at(times)
