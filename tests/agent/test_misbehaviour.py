import numpy as np

from trustfg.agent.gp import Plan
from trustfg.agent.misbehaviour import FALSE_OFFSET_MAX_M, FALSE_OFFSET_MIN_M, maybe_falsify


def test_falsification_rate_and_size_are_as_documented():
    plan = Plan(0.0, 0.5, np.zeros((5, 2)), np.ones((5, 2)))
    for seed in range(5):
        rng = np.random.default_rng(seed)
        shown = [maybe_falsify(plan, 0.4, rng) for _ in range(2000)]
        rate = np.mean([lied for _, lied in shown])
        assert abs(rate - 0.4) < 0.04
        for shared, lied in shown:
            offset = shared.positions - plan.positions
            if lied:
                assert np.allclose(offset, offset[0])  # the whole plan moves
                assert FALSE_OFFSET_MIN_M <= np.linalg.norm(offset[0]) <= FALSE_OFFSET_MAX_M
                assert np.array_equal(shared.velocities, plan.velocities)
            else:
                assert shared is plan


def test_falsification_is_deterministic_per_seed():
    plan = Plan(0.0, 0.5, np.zeros((5, 2)), np.ones((5, 2)))
    a = [maybe_falsify(plan, 0.4, np.random.default_rng(3))[0].positions[0] for _ in range(1)]
    b = [maybe_falsify(plan, 0.4, np.random.default_rng(3))[0].positions[0] for _ in range(1)]
    assert np.array_equal(a, b)


def test_honest_cars_never_falsify():
    plan = Plan(0.0, 0.5, np.zeros((5, 2)), np.ones((5, 2)))
    rng = np.random.default_rng(0)
    assert not any(maybe_falsify(plan, 0.0, rng)[1] for _ in range(1000))
