"""The attack suite (agent.attacks): each liar lies as documented, and only as documented."""

import numpy as np
import pytest

from trustfg.agent.attacks import Liar
from trustfg.agent.config import ConfigError, liar_attack, parse_attack
from trustfg.agent.config.attacks import AttackConfig
from trustfg.agent.gp import Plan
from trustfg.agent.messages import PeerTrust, TrustReport
from trustfg.agent.planner import PeerConstraint, PlanRequest
from trustfg.agent.sightings import Motion

NOW = 10.0


def cruising_plan(t0: float = NOW, speed: float = 0.4) -> Plan:
    """Along +x at ``speed`` from the origin, 9 states 0.5 s apart."""
    times = 0.5 * np.arange(9)
    return Plan(t0, 0.5, np.c_[speed * times, np.zeros(9)], np.tile([speed, 0.0], (9, 1)))


def motion(x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> Motion:
    return Motion(NOW, np.array([x, y]), np.array([vx, vy]), np.zeros(2), 0.0)


def liar(name: str, seed: int = 0, partners=frozenset(), **params) -> Liar:
    return Liar(1, AttackConfig(name, params), np.random.default_rng(seed), partners)


def test_displaced_rate_and_size_are_as_documented():
    plan = cruising_plan()
    for seed in range(3):
        shown = [liar("displaced", seed).plan(plan, NOW, None, {}) for _ in range(1)]
        lying = liar("displaced", seed, p=0.4)
        told = [lying.plan(plan, NOW + 0.2 * k, None, {})[0] for k in range(2000)]
        offsets = [p.positions - plan.positions for p in told]
        moved = [o for o in offsets if np.any(o)]
        assert abs(len(moved) / 2000 - 0.4) < 0.04
        assert lying.counters["plans_falsified"] == len(moved)
        for o in moved:
            assert np.allclose(o, o[0]) and 0.4 <= np.linalg.norm(o[0]) <= 0.8  # the whole plan moves
        assert shown[0][1] == NOW  # stamps stay true


def test_a_liar_is_deterministic_per_seed():
    plan = cruising_plan()
    a = [liar("displaced", 3).plan(plan, NOW, None, {})[0].positions for _ in range(1)]
    b = [liar("displaced", 3).plan(plan, NOW, None, {})[0].positions for _ in range(1)]
    assert np.array_equal(a, b)


def test_forged_stamps_shift_the_stamp_not_the_plan():
    plan = cruising_plan()
    told, stamp = liar("forged-future", p=0.0).plan(plan, NOW, None, {})
    assert stamp == pytest.approx(NOW + 0.2) and told is plan
    _, stamp = liar("forged-past", p=0.0).plan(plan, NOW, None, {})
    assert stamp == pytest.approx(NOW - 0.2)
    _, stamp = liar("forged-future", p=0.0, shift_s=0.5).plan(plan, NOW, None, {})
    assert stamp == pytest.approx(NOW + 0.5)


@pytest.mark.parametrize("name, shift_s", [("forged-future", -0.1), ("forged-future", 0.0), ("forged-past", 0.1)])
def test_a_forged_stamp_on_the_wrong_side_is_refused(name, shift_s):
    with pytest.raises(ConfigError, match="shift_s"):
        AttackConfig(name, {"shift_s": shift_s}).validate("cars[0].attack")



def test_bias_moves_every_plan_away_from_the_nearest_car():
    plan = cruising_plan()
    own = motion(0.0, 0.0)
    seen = {2: motion(0.0, 1.0), 3: motion(3.0, 0.0)}
    told, _ = liar("bias", bias_m=0.14).plan(plan, NOW, own, seen)
    assert np.allclose(told.positions - plan.positions, [0.0, -0.14])  # away from car 2, the nearest
    told, _ = liar("bias", bias_m=0.14, victim=3, direction=-1).plan(plan, NOW, own, seen)
    assert np.allclose(told.positions - plan.positions, [0.14, 0.0])  # towards car 3


def test_false_future_is_true_now_and_bends_later():
    plan = cruising_plan()
    told, _ = liar("false-future", bend_m=0.6, ramp_s=1.0).plan(plan, NOW, None, {})
    assert np.allclose(told.position_at(NOW), plan.position_at(NOW))
    later = told.position_at(NOW + 2.0) - plan.position_at(NOW + 2.0)
    assert np.allclose(later, [[0.0, 0.6]], atol=1e-6)  # left of +x


def test_false_yield_is_true_now_and_announces_a_stop_it_does_not_make():
    plan = cruising_plan()
    told, _ = liar("false-yield", stop_s=0.5).plan(plan, NOW, None, {})
    assert np.allclose(told.position_at(NOW), plan.position_at(NOW))
    stop = told.position_at(NOW + 3.0)[0, 0]
    assert stop == pytest.approx(0.4 * 0.25, abs=0.01)  # braked, it stands 0.1 m on
    assert plan.position_at(NOW + 3.0)[0, 0] == pytest.approx(1.2)


def test_on_off_lies_only_in_its_bursts():
    plan = cruising_plan()
    lying = liar("on-off", on_s=1.0, off_s=4.0)
    lied = [np.any(lying.plan(plan, NOW + t, None, {})[0].positions != plan.positions)
            for t in np.arange(0.0, 10.0, 0.2)]
    times = np.arange(0.0, 10.0, 0.2)
    assert all(lie == ((t % 5.0) < 1.0 - 1e-9) for t, lie in zip(times, lied))


def test_replay_claims_it_is_where_it_was():
    lying = liar("replay", p=1.0, age_s=1.0)
    for k in range(6):  # 1 s of true plans, each starting where the car is
        t = NOW + 0.2 * k
        lying.plan(cruising_plan(t).shifted([0.4 * 0.2 * k, 0.0]), t, None, {})
    t = NOW + 1.2
    told, stamp = lying.plan(cruising_plan(t).shifted([0.48, 0.0]), t, None, {})
    assert stamp == t
    assert told.position_at(t)[0, 0] == pytest.approx(0.08, abs=1e-6)  # where it was 1 s earlier


def report_about(*peers) -> TrustReport:
    return TrustReport(1, 1, NOW, {p: PeerTrust((5.0, 5.0, 5.0), (1.0, 1.0, 1.0), (0.8,) * 3, 0.8, 0.45) for p in peers})


def test_testimony_lies():
    report = report_about(2, 3)
    swapped = liar("false-testimony").testimony(report)
    assert swapped.peers[2].alpha == (1.0,) * 3 and swapped.peers[2].beta == (5.0,) * 3
    slander = liar("slander", amount=30.0, target=2).testimony(report)
    assert slander.peers[2].beta == (30.0,) * 3 and slander.peers[2].alpha == (0.0,) * 3
    assert slander.peers[3] == report.peers[3]
    praise = liar("praise", amount=30.0).testimony(report)
    assert all(pt.alpha == (30.0,) * 3 and pt.beta == (0.0,) * 3 for pt in praise.peers.values())
    collude = liar("collude", partners=frozenset({3})).testimony(report)
    assert collude.peers[3].alpha == (30.0,) * 3  # backs its partner
    assert collude.peers[2].alpha == (1.0,) * 3  # and slanders the honest


def test_framing_steers_behind_its_victim_and_blames_it():
    framer = liar("framing", gap_m=0.35)
    seen = {2: motion(1.0, 0.0, vx=0.4), 3: motion(-3.0, 0.0)}
    victim_plan = cruising_plan()
    request = PlanRequest(t_now=NOW, position=np.zeros(2), velocity=np.zeros(2), goal=np.array([-2.0, 2.0]),
                          t_arrive=NOW + 10.0, epsilon_obstacle=0.25, route=((0.0, 1.0),), lane=((0.0, 0.0),))
    steered, peers = framer.steer(request, [(2, PeerConstraint(victim_plan, 0.9)), (3, PeerConstraint(victim_plan, 0.9))],
                                  NOW, seen)
    assert framer.victim == 2
    assert np.allclose(steered.goal, [0.65, 0.0])
    assert dict(peers)[2].epsilon == 0.35 and dict(peers)[3].epsilon == 0.9
    blamed = framer.testimony(report_about(2, 3))
    assert blamed.peers[2].beta[0] == 30.0 and blamed.peers[3] == report_about(3).peers[3]


def test_attack_config_is_checked():
    assert parse_attack("bias", ["bias_m=0.1"]).params == {"bias_m": 0.1}
    for name, params, what in [("nonsense", [], "unknown attack"), ("bias", ["p=0.5"], "not a parameter"),
                               ("displaced", ["p=2"], r"within \[0, 1\]"), ("bias", ["victim=1.5"], "car id"),
                               ("bias", ["bias_m"], "KEY=NUMBER"), ("displaced+displaced", [], "twice")]:
        with pytest.raises(ConfigError, match=what):
            parse_attack(name, params)
    assert liar_attack(None, 0.3).params == {"p": 0.3}
    assert liar_attack(AttackConfig("bias"), 0.3).params == {}  # bias has no p
