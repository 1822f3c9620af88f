"""What a process run's recordings say about a liar: when its first lie came due."""

import dataclasses
import json

import numpy as np

from trustfg.agent.config import AttackConfig
from trustfg.fleet.sim.trust_record import lies_due


def _scenario(lab, liar):
    cars = tuple(dataclasses.replace(c, attack=AttackConfig("displaced") if c.id == liar else None)
                 for c in lab.cars)
    return dataclasses.replace(lab, cars=cars)


def _plan_record(car, seq, stamp, positions):
    positions = np.asarray(positions, float)
    return {"t": stamp + 0.01, "sender": car, "kind": "plan", "message": {
        "kind": "plan", "id": car, "seq": seq, "stamp": stamp, "t0": stamp, "dt": 0.5, "goal": [0.0, 0.0],
        "positions": positions.tolist(), "velocities": np.zeros_like(positions).tolist()}}


def test_a_liar_that_stands_telling_the_truth_has_told_no_lie_until_it_does(lab, tmp_path):
    """Truthful plans while it stands (after its departure), then one displaced 0.5 m at
    10 s: its first lie comes due at that plan's stamp (10 s after the go), not before;
    an honest car's plans, displaced or not, are no liar's."""
    scenario = _scenario(lab, liar=lab.cars[0].id)
    ids = [c.id for c in scenario.cars]
    t_go = 1000.0
    times = t_go + np.arange(0.0, 20.0, 0.05)
    states = np.zeros((len(times), len(ids), 5))  # every car stands at the origin
    records = [_plan_record(ids[0], k, t_go + 0.1 * k, [[0.0, 0.0]] * 5) for k in range(100)]
    records.append(_plan_record(ids[0], 100, t_go + 10.0, [[0.5, 0.0]] * 5))
    records.append(_plan_record(ids[1], 1, t_go + 2.0, [[0.9, 0.0]] * 5))  # honest car: not the liar's
    path = tmp_path / "messages.jsonl"
    path.write_text("".join(json.dumps(r) + "\n" for r in records))
    # held to its word to its end (no plan after it): a lie that goes on for 2 s
    assert lies_due(scenario, path, times, states, t_go) == {"first_lie_due_s": 10.0, "sustained_lie_due_s": 10.0}
    path.write_text("".join(json.dumps(r) + "\n" for r in records[:100]))
    assert lies_due(scenario, path, times, states, t_go) == {"first_lie_due_s": None, "sustained_lie_due_s": None}
