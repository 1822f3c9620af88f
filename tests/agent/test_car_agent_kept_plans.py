"""Kept plans (verify.keep_s): a replan keeps the current plan only while it still verifies
against what the car knows now, the car tracks it, and it is young enough."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.car_agent import CarAgent
from trustfg.agent.gp import standing
from trustfg.agent.messages import PlanMessage
from trustfg.agent.safe_plan import KEPT

FRAME_S = 0.05
PEER = 2


def agent_of(intersection, intersection_sdf, keep_s: float) -> CarAgent:
    alone = dataclasses.replace(intersection, cars=intersection.cars[:2],
                                verify=dataclasses.replace(intersection.verify, keep_s=keep_s))
    return CarAgent(alone.cars[0], alone, intersection_sdf)


def drive(agent: CarAgent, t_from: float, t_to: float, offset=(0.0, 0.0), peer_at=None) -> list[str]:
    """The car follows its plan exactly (shifted by ``offset``), replanning every period;
    ``peer_at``: where the peer stands, seen. Returns the replans' outcomes."""
    outcomes, period = [], agent.scenario.control.replan_period_s
    next_replan = t_from
    for t in np.arange(t_from, t_to, FRAME_S):
        here = agent.plan.position_at(t) if agent.plan is not None else agent.car.start
        x, y = np.ravel(here) + offset
        agent.observe(t, agent.car.id, float(x), float(y), np.pi / 2)
        if peer_at is not None:
            agent.observe(t, PEER, *peer_at, 0.0)
        agent.gather_evidence(t)
        if t + 1e-9 >= next_replan:
            next_replan += period
            agent.replan(t)
            outcomes.append(agent.last_outcome.outcome)
    return outcomes


def test_off_by_default_every_replan_optimises(intersection, intersection_sdf):
    assert intersection.verify.keep_s == 0.0
    agent = agent_of(intersection, intersection_sdf, 0.0)
    assert KEPT not in drive(agent, 0.0, 3.0)


@pytest.mark.parametrize("keep_s", [0.6, 1.0])
def test_a_clear_way_keeps_the_plan_until_it_is_keep_s_old(intersection, intersection_sdf, keep_s):
    agent = agent_of(intersection, intersection_sdf, keep_s)
    outcomes = drive(agent, 0.0, 4.0)
    assert outcomes.count(KEPT) >= len(outcomes) // 2
    optimised_runs = "".join("k" if o == KEPT else "o" for o in outcomes).split("o")
    period = intersection.control.replan_period_s
    assert max(len(run) for run in optimised_runs) * period <= keep_s + 1e-9  # never kept past keep_s
    assert agent.counters["plans_kept"] == outcomes.count(KEPT)


def test_a_peer_that_steps_into_the_kept_plan_gets_a_new_plan(intersection, intersection_sdf):
    """The kept plan is verified against the peer's newest plan: one standing on it ends
    the keeping at once (without the check the car would keep a plan through the peer)."""
    agent = agent_of(intersection, intersection_sdf, 5.0)
    assert drive(agent, 0.0, 2.0)[-1] == KEPT
    ahead = np.ravel(agent.plan.position_at(3.5))  # where the kept plan has us 1.5 s from now
    t = 2.0
    agent.receive(PlanMessage(PEER, 1, t, standing(ahead, t), tuple(ahead)), t)
    kept = agent.plan
    assert drive(agent, t, t + 0.1, peer_at=tuple(ahead)) == [agent.last_outcome.outcome]
    assert agent.last_outcome.outcome != KEPT and agent.plan is not kept
    times = np.linspace(t, agent.plan.t_end, 400)
    breach = agent.scenario.safety.breach_distance(agent.car.radius_m, agent.radius(PEER))
    assert np.min(np.linalg.norm(agent.plan.position_at(times) - ahead, axis=1)) > breach


def test_a_car_off_its_plan_gets_a_new_plan(intersection, intersection_sdf):
    agent = agent_of(intersection, intersection_sdf, 5.0)
    assert drive(agent, 0.0, 2.0)[-1] == KEPT
    assert KEPT not in drive(agent, 2.0, 2.2, offset=(0.12, 0.0))  # 12 cm off: tracked no more
