"""The attack suite: which attacks it runs, against which fleets."""

from trustfg.agent.config import ATTACKS
from trustfg.fleet.experiments.adversaries import ATTACKS as SUITE
from trustfg.fleet.experiments.adversaries import LIAR, PARTNER


def test_the_suite_runs_every_attack_a_fleet_can_be_given():
    """One list of attack names: what ``trustfg sim --attack`` takes is what the suite runs."""
    assert list(SUITE) == list(ATTACKS)


def test_each_attack_of_the_suite_is_run_by_the_liar_and_collusion_by_two():
    for name, cars in SUITE.items():
        assert cars[LIAR].names == (name,)
        assert set(cars) == ({LIAR, PARTNER} if name == "collude" else {LIAR})
