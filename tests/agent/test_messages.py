import math

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustfg.agent import messages
from trustfg.agent.gp import Plan
from trustfg.agent.message_fields import numbers
from trustfg.agent.messages import (
    Inbox,
    MessageError,
    PeerTrust,
    PlanMessage,
    PoseMessage,
    StatusMessage,
    TrustReport,
    decode,
    encode,
)


def plan_message(sender=2, seq=1, n=21):
    rng = np.random.default_rng(seq)
    plan = Plan(10.0, 0.5, rng.normal(size=(n, 2)), rng.normal(size=(n, 2)))
    return PlanMessage(sender, seq, 10.01, plan, (0.4, 2.15))


def samples():
    return [
        plan_message(),
        TrustReport(3, 7, 12.5, {1: PeerTrust((1.0, 2.0, 3.0), (0.0, 0.5, 9.0), (0.9, 0.8, 0.3), 0.3, 0.9),
                                 4: PeerTrust((5.0,) * 3, (0.0,) * 3, (0.97,) * 3, 0.97, 0.45)}),
        PoseMessage(4, 99, 13.0, 0.4, -2.15, 1.5708, True),
        StatusMessage(1, 3, 14.0, "driving", 4.2, 5, False, {"plans_rejected": 2, "replans": 40}, 7),
        messages.StartMessage(messages.operator_seq(15.0), 15.0, 3, {1: (17.0, 0.4), 2: (17.5, 0.35)}),
        messages.StopMessage(messages.operator_seq(16.0), 16.0, "estop", (1, 3)),
        messages.StopMessage(messages.operator_seq(16.5), 16.5, "abort", (), 3),
        messages.HeartbeatMessage(messages.operator_seq(17.0), 17.0),
        messages.ClockMessage(2, 0, 18.25),
    ]


@pytest.mark.parametrize("message", samples(), ids=lambda m: m.kind)
def test_round_trip(message):
    again = decode(encode(message))
    assert type(again) is type(message)
    assert (again.sender, again.seq, again.stamp) == (message.sender, message.seq, message.stamp)
    if isinstance(message, PlanMessage):
        assert np.array_equal(again.plan.positions, message.plan.positions)
        assert np.array_equal(again.plan.velocities, message.plan.velocities)
        assert (again.plan.t0, again.plan.dt, again.goal) == (message.plan.t0, message.plan.dt, message.goal)
    else:
        assert again == message


def test_a_plan_tells_how_many_deadlocks_its_car_has_been_through_and_bad_counts_are_refused():
    been_through = PlanMessage(2, 1, 10.01, plan_message().plan, (0.4, 2.15), deadlocks=3)
    assert decode(encode(been_through)).deadlocks == 3
    assert "deadlocks" not in msgpack.unpackb(encode(plan_message()))  # the field only when > 0
    assert decode(encode(plan_message())).deadlocks == 0
    assert messages.from_dict(messages.to_dict(been_through)).deadlocks == 3
    for bad in (-1, 2.5, True, "3", 2**40):
        with pytest.raises(MessageError, match="deadlocks"):
            decode(mutate(been_through, deadlocks=bad))


def test_a_stuck_plan_says_so_and_a_plan_without_the_field_is_not_stuck():
    stuck = PlanMessage(2, 1, 10.01, plan_message().plan, (0.4, 2.15), stuck=True)
    assert decode(encode(stuck)).stuck is True
    assert "stuck" not in msgpack.unpackb(encode(plan_message()))  # the field only when true
    assert decode(encode(plan_message())).stuck is False
    assert messages.from_dict(messages.to_dict(stuck)).stuck is True
    with pytest.raises(MessageError, match="stuck"):
        decode(mutate(stuck, stuck=1))
    with pytest.raises(MessageError, match="stuck"):  # a recording goes through the same check
        messages.from_dict(messages.to_dict(stuck) | {"stuck": "yes"})


def test_golden_bytes_of_a_pose():
    """The wire format is a contract with other implementations: pin one encoding."""
    payload = encode(PoseMessage(4, 99, 13.0, 0.5, -2.0, 1.5, True))
    assert payload.hex() == (
        "89a17601a16ba4706f7365a2696404a373657163a174cb402a000000000000a178cb3fe0000000000000"
        "a179cbc000000000000000a3796177cb3ff8000000000000a576616c6964c3")


def mutate(message: dict, **changes) -> bytes:
    body = msgpack.unpackb(encode(message), strict_map_key=False)
    for key, value in changes.items():
        if value is ...:
            body.pop(key)
        else:
            body[key] = value
    return msgpack.packb(body)


@pytest.mark.parametrize("changes, reason", [
    (dict(v=2), "schema version"),
    (dict(k="teleport"), "unknown message kind"),
    (dict(id=0), "id"),
    (dict(id=True), "id"),
    (dict(seq=-1), "seq"),
    (dict(t=float("nan")), "not finite"),
    (dict(dt=0.0), "dt"),
    (dict(pos=[0.0] * 41), "2N floats"),
    (dict(pos=[0.0] * 2), "pos"),
    (dict(pos=[0.0] * 40 + [float("inf"), 0.0]), "not finite"),
    (dict(pos="abc"), "expected an array"),
    (dict(goal=[1.0]), "goal"),
    (dict(extra=1), "unexpected field"),
    (dict(vel=...), "missing field"),
])
def test_invalid_plans_are_refused_with_a_reason(changes, reason):
    with pytest.raises(MessageError, match=reason):
        decode(mutate(plan_message(), **changes))


def test_oversized_and_non_msgpack_payloads():
    with pytest.raises(MessageError, match="exceeds"):
        decode(b"\x00" * (messages.MAX_MESSAGE_BYTES + 1))
    with pytest.raises(MessageError, match="not msgpack"):
        decode(b"\xc1")
    with pytest.raises(MessageError, match="expected a map"):
        decode(msgpack.packb([1, 2, 3]))
    with pytest.raises(MessageError):
        decode("text")  # type: ignore[arg-type]


@settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=2048))
def test_random_bytes_only_ever_raise_message_error(data):
    try:
        decode(data)
    except MessageError:
        pass


@settings(max_examples=1500, deadline=None)
@given(st.sampled_from([encode(m) for m in samples()]), st.data())
def test_mutated_messages_only_ever_raise_message_error(payload, data):
    raw = bytearray(payload)
    for _ in range(data.draw(st.integers(1, 6))):
        action = data.draw(st.sampled_from(["flip", "cut", "insert"]))
        if action == "flip" and raw:
            i = data.draw(st.integers(0, len(raw) - 1))
            raw[i] ^= data.draw(st.integers(1, 255))
        elif action == "cut" and raw:
            raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
        else:
            i = data.draw(st.integers(0, len(raw)))
            raw[i:i] = data.draw(st.binary(min_size=1, max_size=8))
    try:
        message = decode(bytes(raw))
    except MessageError:
        return
    # Whatever decodes is fully valid: finite numbers, sane ids (0: the operator's kinds only).
    low = 0 if message.kind in messages.OPERATOR_KINDS else 1
    assert low <= message.sender <= 255 and math.isfinite(message.stamp)


def test_inbox_drops_spoofed_replayed_and_out_of_order():
    inbox = Inbox()
    first, second = encode(plan_message(seq=5)), encode(plan_message(seq=6))
    assert inbox.accept(first, key_sender=2) is not None
    assert inbox.accept(first, key_sender=2) is None  # replay
    assert inbox.accept(second, key_sender=2) is not None
    assert inbox.accept(encode(plan_message(seq=4)), key_sender=2) is None  # out of order
    assert inbox.accept(encode(plan_message(sender=3, seq=1)), key_sender=2) is None  # spoofed
    assert inbox.accept(b"garbage", key_sender=2) is None
    assert inbox.dropped == {"replayed": 1, "out_of_order": 1, "spoofed_sender": 1, "invalid": 1}
    assert inbox.accepted["plan"] == 2


def test_inbox_accepts_a_restarted_sender():
    inbox = Inbox(restart_after_s=2.0)
    late = plan_message(seq=500)
    assert inbox.accept(encode(late)) is not None
    restarted = PlanMessage(2, 1, late.stamp + 5.0, late.plan, late.goal)
    assert inbox.accept(encode(restarted)) is not None
    # ... but an old message with a small sequence number is still a replay.
    assert inbox.accept(encode(PlanMessage(2, 0, late.stamp - 1.0, late.plan, late.goal))) is None


@pytest.mark.parametrize("message, changes, reason", [
    (messages.StopMessage(1, 1.0, "estop"), dict(action="launch"), "stop.action"),
    (messages.StopMessage(1, 1.0, "estop"), dict(cars=[0]), "stop.cars"),
    (messages.StopMessage(1, 1.0, "estop"), dict(cars="all"), "stop.cars"),
    (messages.StopMessage(1, 1.0, "estop"), dict(id=3), "id"),
    (messages.StartMessage(1, 1.0, 2, {1: (2.0, 0.4)}), dict(trial=0), "trial"),
    (messages.StartMessage(1, 1.0, 2, {1: (2.0, 0.4)}), dict(trial=...), "missing"),
    (messages.HeartbeatMessage(1, 1.0), dict(extra=1), "unexpected"),
    (messages.ClockMessage(2, 0, 1.0), dict(id=0), "id"),
])
def test_operator_messages_are_checked(message, changes, reason):
    with pytest.raises(MessageError, match=reason):
        decode(mutate(message, **changes))


def test_operator_messages_from_several_processes_share_one_order():
    """Two operator processes (trustfg stop, the dashboard) number by their stamps: the
    later stop wins whichever process sent it, and an old one replayed is dropped."""
    inbox = Inbox()
    first = messages.StopMessage(messages.operator_seq(100.0), 100.0, "estop")
    second = messages.StopMessage(messages.operator_seq(100.5), 100.5, "release")
    assert inbox.accept(encode(first), key_sender=0) == first
    assert inbox.accept(encode(second), key_sender=0) == second
    assert inbox.accept(encode(first), key_sender=0) is None and inbox.dropped["out_of_order"] == 1


def test_an_identical_copy_is_judged_without_decoding_it_again(monkeypatch):
    """Every new plan comes twice (best effort and reliably): the second copy is the same
    message, dropped as the same replay, without a second decode."""
    inbox = Inbox()
    first, second = encode(plan_message(seq=5)), encode(plan_message(seq=6))
    decoded = []
    real_decode = messages.decode
    monkeypatch.setattr(messages, "decode", lambda payload: decoded.append(payload) or real_decode(payload))
    assert inbox.accept(first, key_sender=2) is not None
    assert inbox.accept(memoryview(first), key_sender=2) is None
    assert inbox.accept(second, key_sender=2) is not None
    assert inbox.accept(first, key_sender=2) is None  # older than the last: out of order, as decoded
    assert len(decoded) == 2
    assert inbox.dropped == {"replayed": 1, "out_of_order": 1}
    assert inbox.accept(first, key_sender=3) is None and inbox.dropped["spoofed_sender"] == 1  # another key: decoded
    assert len(decoded) == 3


@pytest.mark.parametrize("values, bounds, expected", [
    ([0.5, -2.0], (-1e6, 1e6), [0.5, -2.0]),
    ([1, 2.5], (-1e6, 1e6), [1.0, 2.5]),  # integers are numbers too
    ([1e308, 1e308], (0.0, 1.7e308), [1e308, 1e308]),  # in range, though their sum is not finite
    ([float("nan"), 1.0], (-1e6, 1e6), "not finite"),
    ([1.0, float("inf")], (-1e6, 1e6), "not finite"),
    ([float("-inf"), float("inf")], (-1e6, 1e6), "not finite"),
    ([0.5, 2e6], (-1e6, 1e6), "outside"),
    ([True, 1.0], (-1e6, 1e6), "expected numbers"),
    (["1.0"], (-1e6, 1e6), "expected numbers"),
])
def test_an_array_of_numbers_is_read_whole_or_refused(values, bounds, expected):
    if isinstance(expected, str):
        with pytest.raises(MessageError, match=expected):
            numbers({"a": values}, "a", 1, 4, *bounds)
    else:
        out = numbers({"a": values}, "a", 1, 4, *bounds)
        assert out == expected and all(type(x) is float for x in out)
