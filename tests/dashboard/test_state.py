"""FleetView, the dashboard's pure logic: alerts, rates, distances, snapshot shape."""

import dataclasses

import numpy as np

from trustfg.agent import messages
from trustfg.agent.config import PALETTE
from trustfg.agent.gp import Plan
from trustfg.dashboard.state import LOW_TRUST, FleetView, css_color


def pose(car, t, x, y, valid=True):
    return messages.PoseMessage(car, int(t * 100), t, x, y, 0.0, valid)


def test_breach_and_running_min_distance(intersection):
    view = FleetView(intersection)
    view.update(pose(1, 1.0, 0.0, 0.0), 1.0)
    view.update(pose(2, 1.0, 0.25, 0.0), 1.0)
    kinds = {a["kind"] for a in view.alerts()}
    assert "breach" in kinds
    view.update(pose(2, 1.1, 1.0, 0.0), 1.1)
    assert "breach" not in {a["kind"] for a in view.alerts()}
    assert view.min_distance[0, 1] == 0.25  # the running minimum keeps the close call


def test_low_trust_stale_and_lost_pose(intersection):
    view = FleetView(intersection)
    report = messages.TrustReport(2, 1, 1.0, {1: messages.PeerTrust((0,) * 3, (9,) * 3, (0.9, 0.9, 0.3), 0.3, 0.9),
                                              3: messages.PeerTrust((9,) * 3, (0,) * 3, (0.9,) * 3, 0.95, 0.45)})
    view.update(report, 1.0)
    view.update(pose(3, 1.0, 0.0, 0.0, valid=False), 1.0)
    view.update(pose(4, 1.0, 2.0, 2.0), 1.0)
    view.update(pose(4, 5.0, 2.0, 2.0), 5.0)  # time moves on; 2 and 3 go quiet
    alerts = {(a["kind"], tuple(a["cars"])) for a in view.alerts()}
    assert ("low_trust", (2, 1)) in alerts and ("low_trust", (2, 3)) not in alerts
    assert ("lost_pose", (3,)) in alerts and ("stale_peer", (2,)) in alerts
    view.liveliness(4, False)
    assert ("stale_peer", (4,)) in {(a["kind"], tuple(a["cars"])) for a in view.alerts()}
    assert LOW_TRUST == 0.6


def test_snapshot_shape_and_plan_sampling(intersection):
    view = FleetView(intersection)
    plan = Plan(0.0, 1.0, np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]), np.zeros((3, 2)))
    view.update(messages.PlanMessage(1, 1, 0.0, plan, (2.0, 0.0)), 0.5)
    snapshot = view.snapshot()
    car = snapshot["cars"][0]
    assert car["plan"][0][0] >= 0.0 and car["plan"][-1] == [2.0, 0.0]
    assert car["rates"]["plan"] == 0.5
    assert snapshot["min_distance"]["ids"] == [1, 2, 3, 4]
    assert view.map()["cars"][0]["color"].startswith("#")


def test_truth_takes_over_the_distances(intersection):
    view = FleetView(intersection)
    view.update(pose(1, 1.0, 0.0, 0.0), 1.0)
    view.update(pose(2, 1.0, 0.5, 0.0), 1.0)
    view.truth(1.0, {1: (0.0, 0.0), 2: (0.8, 0.0), 3: (5, 5), 4: (9, 9)})
    assert view.distance_source == "ground truth" and view.min_distance[0, 1] == 0.8


def test_css_colours():
    assert css_color("tab:blue") == "#1f77b4"
    assert css_color("no-such-colour") == "#7f7f7f"


def test_cars_without_a_colour_take_the_palette_in_order(intersection):
    plain = dataclasses.replace(intersection, cars=tuple(dataclasses.replace(c, color="") for c in intersection.cars))
    view = FleetView(plain)
    assert [view.cars[c.id].color for c in plain.cars] == [css_color(name) for name in PALETTE[:len(plain.cars)]]


def test_a_car_whose_clock_is_off_is_shown_and_alerted(intersection):
    """Each peer's status carries its estimate of car 2's clock; the page shows the median
    and alerts past CLOCK_ALERT_S; a car a few ms off is not alerted."""
    from trustfg.fleet.car.report import clock_counters
    view = FleetView(intersection)
    for reporter, seen in ((1, {2: 0.31, 3: -0.002}), (3, {2: 0.29}), (4, {2: 0.30, 3: 0.003})):
        view.update(messages.StatusMessage(reporter, 1, 1.0, "driving", 5.0, 1, False, clock_counters(seen)), 1.0)
    cars = {c["id"]: c for c in view.snapshot()["cars"]}
    assert cars[2]["clock_offset_ms"] == 300.0 and abs(cars[3]["clock_offset_ms"]) < 5
    assert cars[1]["clock_offset_ms"] is None
    alerts = {(a["kind"], tuple(a["cars"])) for a in view.alerts()}
    assert ("clock", (2,)) in alerts and ("clock", (3,)) not in alerts


def test_each_car_shows_how_its_replans_ended(intersection):
    view = FleetView(intersection)
    assert view.snapshot()["cars"][0]["outcomes"] is None
    counters = {"plans_first": 40, "plans_retry": 3, "plans_fallback": 2, "plans_kept": 7, "deadlocks": 1,
                "deadlock_steps_aside": 1}
    view.update(messages.StatusMessage(1, 1, 1.0, "driving", 5.0, 2, False, counters), 1.0)
    assert view.snapshot()["cars"][0]["outcomes"] == {"first": 40, "retry": 3, "fallback": 2, "kept": 7,
                                                       "deadlocks": 1, "aside": 1}
