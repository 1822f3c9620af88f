"""The witness's evidence (agent.witness) mounts at the same pace however often a car looks:
a pass counts for its whole evidence period."""

from dataclasses import replace

import numpy as np
import pytest

from trustfg.agent.car_agent import CarAgent
from trustfg.agent.gp import Plan
from trustfg.agent.messages import PlanMessage
from trustfg.agent.trust import CONSISTENCY, SAFETY

PEER, OBSERVER = 1, 2
FRAME_S = 0.02
SECONDS = 5.0


def watched(scenario, sdf, period_s: float, seed: int, towards_observer: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """(alpha, beta) of the observer's own evidence about the peer after SECONDS, without the
    prior, and how many safety pieces it counted: the peer drives east along y = 0 from x =
    -1.5 at 0.1 m/s for 4 s and tells its plans; the observer stands at x = -1 on that line
    (``towards_observer``: the peer drives into it, slowly, for seconds) or 2 m to the side."""
    scenario = replace(scenario, trust=replace(scenario.trust, evidence_period_s=period_s))
    observer = CarAgent(scenario.car(OBSERVER), scenario, sdf)
    rng = np.random.default_rng(seed)
    speed, stop_s, seq = 0.1, 4.0, 0
    stands = np.array([-1.0, 0.0]) if towards_observer else np.array([-1.0, 2.0])
    for k in range(int(SECONDS / FRAME_S)):
        t = k * FRAME_S
        at = np.array([-1.5 + speed * min(t, stop_s), 0.0])
        observer.observe(t, PEER, *(at + rng.normal(0.0, 0.003, 2)), 0.0)
        observer.observe(t, OBSERVER, *stands, np.pi)
        if k % 10 == 0:
            times = t + 0.25 * np.arange(13)
            positions = np.array([[-1.5 + speed * min(s, stop_s), 0.0] for s in times])
            velocities = np.array([[speed if s < stop_s else 0.0, 0.0] for s in times])
            seq += 1
            observer.receive(PlanMessage(PEER, seq, t, Plan(t, 0.25, positions, velocities), (1.0, 0.0)), t)
        observer.gather_evidence(t)
    said = observer.trust.report(OBSERVER, 1, SECONDS, lambda peer: 0.4, True).peers[PEER]
    return np.array(said.alpha), np.array(said.beta), observer.trust.counters["evidence_safety"]


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("towards_observer", [False, True])
def test_looking_half_as_often_gathers_as_much_evidence(intersection, intersection_sdf, seed, towards_observer):
    alpha_10, beta_10, pieces_10 = watched(intersection, intersection_sdf, 0.1, seed, towards_observer)
    alpha_20, beta_20, pieces_20 = watched(intersection, intersection_sdf, 0.2, seed, towards_observer)
    assert pieces_20 < 0.6 * pieces_10  # half as many looks ...
    for dimension in (SAFETY, CONSISTENCY):  # ... and as much evidence, success and failure
        assert alpha_20[dimension] == pytest.approx(alpha_10[dimension], rel=0.1, abs=0.2)
        assert beta_20[dimension] == pytest.approx(beta_10[dimension], rel=0.15, abs=0.2)
    if towards_observer:  # the peer that drives into the observer is caught either way
        assert beta_10[SAFETY] > 1.0 and beta_20[SAFETY] > 1.0
