"""The experiments' statistics over runs."""

from trustfg.fleet.experiments import stats


def test_the_least_pair_clearance_leaves_out_each_car_with_itself():
    # The diagonal is each car with itself (0.0), not a pair: left in, every fleet would show 0.000 m.
    run = {"min_clearance": [[0.0, 0.31, 0.42], [0.31, 0.0, 0.27], [0.42, 0.27, 0.0]]}
    assert stats.least_pair_clearance(run) == 0.27
