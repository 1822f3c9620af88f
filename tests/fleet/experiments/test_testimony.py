"""The testimony experiment's measures on one seed of corridor-4, car 1 the paper's liar,
every car seeing 1.5 m: the far cars (3 and 4) are its observers; told by car 2, which
starts beside the liar and sees it lie, they distrust it before they see it, and without
testimonies only after (fleet.experiments.testimony)."""

from trustfg.agent.sight import unseen_epsilon
from trustfg.fleet.experiments.paper import run_one, trust_on
from trustfg.fleet.experiments.testimony import observers, prepared, sight_over, sight_summary, with_testimonies


def test_far_cars_are_told_of_the_liar_before_they_see_it():
    base = prepared("corridor-4", 1.5)
    ahead = {}
    for on in (True, False):
        scenario = trust_on(with_testimonies(base, on))
        run, record = run_one(scenario, 0)
        seen = sight_over(scenario, record)
        assert seen[0, 1, 0] and not seen[0, 2, 0]  # car 2 sees the liar at the start, car 3 does not
        found = observers(scenario, record)
        assert [o["observer"] for o in found] == [3, 4]
        met = [o for o in found if o["first_sight_s"] is not None]
        assert met
        ahead[on] = [o["ahead_s"] for o in met]
        summary = sight_summary(scenario, record)
        assert summary["liar_cleared_unseen"] == 0 and not run["breaches"]
        floor = unseen_epsilon(scenario.safety.epsilon_0(0.1, 0.1), scenario.trust)
        assert all(o["liar_epsilon_unseen_m"] >= floor - 1e-9 for o in found)
    assert all(a is not None and a > 1.0 for a in ahead[True])
    assert all(a is None or a <= 0.0 for a in ahead[False])
