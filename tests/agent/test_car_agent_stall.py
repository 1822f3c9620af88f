"""deadlock.leave_lane: a stalled car-like car plans without lane keeping for a while, as
the rule says; by default, and for a car that turns in place, one that gets somewhere, or
one that waits for a car near it that gets somewhere, it keeps its lane."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent import car_agent
from trustfg.agent.car_agent import PASS_HOLD_S, CarAgent

FRAME_S = 0.05


def agent_of(intersection, intersection_sdf, steering: str, rule: str = "nothing-to-wait-for") -> CarAgent:
    vehicle = dataclasses.replace(intersection.vehicle, steering=steering)
    deadlock = dataclasses.replace(intersection.deadlock, leave_lane=rule)
    alone = dataclasses.replace(intersection, cars=intersection.cars[:1], vehicle=vehicle, deadlock=deadlock)
    agent = CarAgent(alone.cars[0], alone, intersection_sdf)
    agent.set_departure(0.0, 0.3)
    return agent


def lanes_while(agent: CarAgent, monkeypatch, t_to: float, follows: bool,
                peer_at=None) -> list[tuple[float, bool]]:
    """Replan every period until ``t_to``; the car follows its plan (``follows``) or stands
    where it started; ``peer_at(t)``: where a peer is, seen (its goal never heard). Returns
    (time, planned with a lane) of every replan."""
    seen: list[tuple[float, bool]] = []
    real = car_agent.plan_safely

    def spy(request, *args, **kwargs):
        seen.append((request.t_now, bool(request.lane)))
        return real(request, *args, **kwargs)

    monkeypatch.setattr(car_agent, "plan_safely", spy)
    start = np.array(agent.car.start, dtype=float)
    heading = float(np.arctan2(*(np.array(agent.car.goal) - start)[::-1]))
    period, next_replan = agent.scenario.control.replan_period_s, 0.0
    for t in np.arange(0.0, t_to, FRAME_S):
        here = np.ravel(agent.plan.position_at(t)) if follows and agent.plan is not None else start
        agent.observe(t, agent.car.id, float(here[0]), float(here[1]), heading)
        if peer_at is not None:
            agent.observe(t, agent.car.id + 1, *peer_at(t), 0.0)
        if t + 1e-9 >= next_replan:
            next_replan += period
            agent.replan(t)
    return seen


@pytest.mark.parametrize("rule, seconds", [("alone", 6.0), ("nothing-to-wait-for", 8.0)])
def test_a_car_like_car_stalled_alone_plans_off_its_lane(intersection, intersection_sdf, monkeypatch, rule,
                                                         seconds):
    agent = agent_of(intersection, intersection_sdf, "car", rule)
    window = intersection.deadlock.window_s
    seen = lanes_while(agent, monkeypatch, seconds, follows=False)
    assert all(lane for t, lane in seen if t < window - 0.3)  # before a whole window: on its lane
    late = [lane for t, lane in seen if t > window + 0.5]
    assert late and not any(late)  # stalled all along: off its lane, held PASS_HOLD_S at a time
    assert PASS_HOLD_S > intersection.control.replan_period_s


@pytest.mark.parametrize("speed, keeps_lane", [(0.0, False), (0.1, True)])
def test_a_car_like_car_stalled_beside_a_car_keeps_its_lane_while_that_car_gets_somewhere(
        intersection, intersection_sdf, monkeypatch, speed, keeps_lane):
    """Beside a car that moves on, a car that stands waits for it on its lane; beside one
    that stands too (a deadlock: we go first, the lower id), nothing moves, and the lane
    gives way."""
    agent = agent_of(intersection, intersection_sdf, "car")
    beside = np.array(agent.car.start, dtype=float) + np.array([0.0, 0.6])
    seen = lanes_while(agent, monkeypatch, 6.0, follows=False,
                       peer_at=lambda t: (float(beside[0] + speed * t), float(beside[1])))
    late = [lane for t, lane in seen if t > intersection.deadlock.window_s + 0.5]
    assert late and all(late) == keeps_lane and any(late) == keeps_lane


def test_by_default_a_stalled_car_like_car_keeps_its_lane(intersection, intersection_sdf, monkeypatch):
    assert intersection.deadlock.leave_lane == "never"
    agent = agent_of(intersection, intersection_sdf, "car", "never")
    seen = lanes_while(agent, monkeypatch, 6.0, follows=False)
    assert len(seen) > 20 and all(lane for _, lane in seen)


def test_a_car_like_car_that_drives_keeps_its_lane(intersection, intersection_sdf, monkeypatch):
    agent = agent_of(intersection, intersection_sdf, "car")
    seen = lanes_while(agent, monkeypatch, 6.0, follows=True)
    assert len(seen) > 20 and all(lane for _, lane in seen)


def test_a_car_that_turns_in_place_keeps_its_lane_when_it_stalls(intersection, intersection_sdf, monkeypatch):
    agent = agent_of(intersection, intersection_sdf, "in-place")
    seen = lanes_while(agent, monkeypatch, 6.0, follows=False)
    assert len(seen) > 20 and all(lane for _, lane in seen)
