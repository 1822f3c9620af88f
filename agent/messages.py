"""Fleet messages: msgpack maps with a schema version, validated field by field.

Every message is a msgpack map with these common keys:

    v     int    schema version (SCHEMA_VERSION)
    k     str    kind: "plan" | "trust" | "pose" | "status" | "clock" | "start" | "stop"
                 | "heartbeat"
    id    int    sender car id, 1..255 (must match N in the key trustfg/F/N/...);
                 0 for the operator's messages (start, stop, heartbeat: keys trustfg/F/KIND)
    seq   int    sender's sequence number for this kind, 0..2^53; the operator's messages
                 are numbered by their stamp in microseconds (operator_seq), so that the
                 several operator processes that may run at once (go, stop, the dashboard)
                 share one order
    t     float  stamp, seconds on the fleet clock

and per kind:

    plan    t0 float, dt float > 0, pos [x0, y0, x1, y1, ...] (2N floats, 2 <= N <= 256),
            vel [...] (2N floats), goal [x, y]; and only when true, stuck true: the car
            is told to drive and does not move (bridge.motion_watch), its plan stands
            where it stands -- no car to give way to (agent.deadlock); and only when > 0,
            deadlocks int >= 0: how many deadlocks the car has been through this trial (the
            crowd lets the car that has been through most go first, agent.deadlock)
    trust   peers {peer_id: {a: [3 floats >= 0], b: [3 floats >= 0], tau: [3 floats in
            [0, 1]], trust: float in [0, 1], eps: float > 0}}; a/b are the sender's DIRECT
            evidence (safety, consistency, transparency) -- testimonies never carry fused
            values, so rumours cannot loop -- tau/trust/eps are what the sender believes
            and keeps (for dashboards; receivers do not fuse them)
    pose    x, y, yaw floats, valid bool (own car, as its NatNet client sees it)
    status  state str (<= 32 chars), replan_ms float >= 0, iterations int >= 0,
            at_goal bool, counters {str: int >= 0} (<= 64 entries), trial int >= 0 (the
            trial the car last took, 0: none)
    clock   nothing more: ``t`` is the car computer's clock when it answered the
            operator's query on trustfg/F/N/clock (trustfg check measures offsets)
    start   trial int >= 1, cars {car_id: {depart: float, cruise: float > 0}}: when each
            car may set off (fleet clock) and at what cruise speed (m/s); operator, id 0
    stop    action "estop" | "release" | "abort", cars [car_id, ...] (empty: every car),
            trial int >= 0 (abort: the trial to end, 0 any); operator, id 0
    heartbeat  nothing more: an operator's session is alive (the cars' deadman)

Decoding checks types, lengths, finiteness and a size cap (MAX_MESSAGE_BYTES) and raises
:class:`MessageError` for anything else -- never another exception. :class:`Inbox`
adds what needs state: the sender id must match the key, and messages out of order or
replayed are dropped; every drop is counted by reason.
"""

from __future__ import annotations

from collections import Counter, deque
from dataclasses import dataclass, field
from typing import Any, Union

import msgpack
import numpy as np

from .gp import Plan
from .message_fields import MessageError
from .message_fields import boolean as _bool
from .message_fields import integer as _int
from .message_fields import number as _float
from .message_fields import numbers as _floats
from .message_fields import only as _only
from .message_fields import string as _str

SCHEMA_VERSION = 1
OPERATOR_KINDS = ("start", "stop", "heartbeat")
"""Kinds only the operator sends (sender id 0, keys trustfg/F/KIND)."""
STOP_ACTIONS = ("estop", "release", "abort")
MAX_MESSAGE_BYTES = 64 * 1024
MAX_PLAN_STATES = 256
MAX_PEERS = 255
MAX_SEQ = 2**53
MAX_DEADLOCKS = 2**16
DIMENSIONS = ("safety", "consistency", "transparency")


@dataclass(frozen=True)
class PlanMessage:
    sender: int
    seq: int
    stamp: float
    plan: Plan
    goal: tuple[float, float]
    stuck: bool = False
    """The car does not move although it is told to (its plan stands where it stands)."""
    deadlocks: int = 0
    """How many deadlocks the car has been through this trial (agent.deadlock's order)."""

    kind = "plan"


@dataclass(frozen=True)
class PeerTrust:
    alpha: tuple[float, float, float]
    beta: tuple[float, float, float]
    tau: tuple[float, float, float]
    trust: float
    epsilon: float


@dataclass(frozen=True)
class TrustReport:
    sender: int
    seq: int
    stamp: float
    peers: dict[int, PeerTrust] = field(default_factory=dict)

    kind = "trust"


@dataclass(frozen=True)
class PoseMessage:
    sender: int
    seq: int
    stamp: float
    x: float
    y: float
    yaw: float
    valid: bool

    kind = "pose"


@dataclass(frozen=True)
class StatusMessage:
    sender: int
    seq: int
    stamp: float
    state: str
    replan_ms: float
    iterations: int
    at_goal: bool
    counters: dict[str, int] = field(default_factory=dict)
    trial: int = 0

    kind = "status"


@dataclass(frozen=True)
class ClockMessage:
    """A car computer's clock, answering the operator's query (stamp = its clock)."""

    sender: int
    seq: int
    stamp: float

    kind = "clock"


@dataclass(frozen=True)
class StartMessage:
    """The operator's go for one trial: departure time and cruise speed per car."""

    seq: int
    stamp: float
    trial: int
    departures: dict[int, tuple[float, float]] = field(default_factory=dict)

    kind = "start"
    sender = 0


@dataclass(frozen=True)
class StopMessage:
    """The operator's stop: ``estop`` (latched until released), ``release`` (of an
    e-stop; the car then waits for a new start) or ``abort`` (the trial ends: cars hold
    and wait), for ``cars`` (empty: every car)."""

    seq: int
    stamp: float
    action: str
    cars: tuple[int, ...] = ()
    trial: int = 0

    kind = "stop"
    sender = 0

    def names(self, car_id: int) -> bool:
        return not self.cars or car_id in self.cars


@dataclass(frozen=True)
class HeartbeatMessage:
    """An operator's session is alive (what the cars' deadman listens for)."""

    seq: int
    stamp: float

    kind = "heartbeat"
    sender = 0


Message = Union[PlanMessage, TrustReport, PoseMessage, StatusMessage, ClockMessage, StartMessage, StopMessage,
                HeartbeatMessage]


def operator_seq(stamp: float) -> int:
    """The sequence number of an operator's message sent at ``stamp``: microseconds."""
    return int(stamp * 1e6)


# --- encoding ---------------------------------------------------------------------------------


def encode(message: Message) -> bytes:
    body: dict[str, Any] = {"v": SCHEMA_VERSION, "k": message.kind, "id": message.sender,
                            "seq": message.seq, "t": float(message.stamp)}
    if isinstance(message, PlanMessage):
        body.update(t0=float(message.plan.t0), dt=float(message.plan.dt),
                    pos=[float(x) for x in np.asarray(message.plan.positions).ravel()],
                    vel=[float(x) for x in np.asarray(message.plan.velocities).ravel()],
                    goal=[float(message.goal[0]), float(message.goal[1])])
        if message.stuck is not False:  # as given: a recording's value meets decode's check
            body["stuck"] = message.stuck
        if message.deadlocks != 0:
            body["deadlocks"] = message.deadlocks
    elif isinstance(message, TrustReport):
        body["peers"] = {
            int(peer): {"a": [float(x) for x in pt.alpha], "b": [float(x) for x in pt.beta],
                        "tau": [float(x) for x in pt.tau], "trust": float(pt.trust),
                        "eps": float(pt.epsilon)}
            for peer, pt in message.peers.items()
        }
    elif isinstance(message, PoseMessage):
        body.update(x=float(message.x), y=float(message.y), yaw=float(message.yaw),
                    valid=bool(message.valid))
    elif isinstance(message, StatusMessage):
        body.update(state=message.state, replan_ms=float(message.replan_ms),
                    iterations=int(message.iterations), at_goal=bool(message.at_goal),
                    counters={str(k): int(v) for k, v in message.counters.items()},
                    trial=int(message.trial))
    elif isinstance(message, StartMessage):
        body["trial"] = int(message.trial)
        body["cars"] = {int(car): {"depart": float(depart), "cruise": float(cruise)}
                        for car, (depart, cruise) in message.departures.items()}
    elif isinstance(message, StopMessage):
        body.update(action=message.action, cars=[int(c) for c in message.cars], trial=int(message.trial))
    elif not isinstance(message, (ClockMessage, HeartbeatMessage)):
        raise TypeError(f"not a trustfg message: {type(message).__name__}")
    return msgpack.packb(body, use_bin_type=True)


# --- decoding ---------------------------------------------------------------------------------


def decode(payload: bytes) -> Message:
    """Bytes -> message; raises MessageError for anything that is not a valid message."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise MessageError(f"payload must be bytes, got {type(payload).__name__}")
    if len(payload) > MAX_MESSAGE_BYTES:
        raise MessageError(f"payload of {len(payload)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        body = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=False,
                               max_array_len=4 * MAX_PLAN_STATES, max_map_len=4 * MAX_PEERS,
                               max_str_len=256, max_bin_len=0, max_ext_len=0)
    except Exception as exc:  # msgpack raises many types (ValueError, ExtraData, ...)
        raise MessageError(f"not msgpack: {type(exc).__name__}: {exc}") from None
    if not isinstance(body, dict):
        raise MessageError(f"expected a map, got {type(body).__name__}")
    version = _int(body, "v", 0, 2**31)
    if version != SCHEMA_VERSION:
        raise MessageError(f"unsupported schema version {version} (this is {SCHEMA_VERSION})")
    kind = _str(body, "k", 16)
    operator = kind in OPERATOR_KINDS
    sender = _int(body, "id", 0 if operator else 1, 0 if operator else 255)
    seq = _int(body, "seq", 0, MAX_SEQ)
    stamp = _float(body, "t")
    if kind == "heartbeat":
        _only(body, set())
        return HeartbeatMessage(seq, stamp)
    if kind == "clock":
        _only(body, set())
        return ClockMessage(sender, seq, stamp)
    if kind == "stop":
        return _decode_stop(body, seq, stamp)
    if kind == "start":
        return _decode_start(body, seq, stamp)
    if kind == "plan":
        return _decode_plan(body, sender, seq, stamp)
    if kind == "trust":
        return _decode_trust(body, sender, seq, stamp)
    if kind == "pose":
        _only(body, {"x", "y", "yaw", "valid"})
        return PoseMessage(sender, seq, stamp, _float(body, "x"), _float(body, "y"),
                           _float(body, "yaw"), _bool(body, "valid"))
    if kind == "status":
        return _decode_status(body, sender, seq, stamp)
    raise MessageError(f"unknown message kind {kind!r}")


def _decode_stop(body: dict, seq: int, stamp: float) -> StopMessage:
    _only(body, {"action", "cars", "trial"})
    action = _str(body, "action", 16)
    if action not in STOP_ACTIONS:
        raise MessageError(f"stop.action: expected one of {', '.join(STOP_ACTIONS)}, got {action!r}")
    cars = body.get("cars")
    if not isinstance(cars, list) or len(cars) > MAX_PEERS:
        raise MessageError(f"stop.cars must be an array of at most {MAX_PEERS} car ids")
    if any(isinstance(c, bool) or not isinstance(c, int) or not 1 <= c <= 255 for c in cars):
        raise MessageError(f"stop.cars: bad car id in {cars!r}")
    return StopMessage(seq, stamp, action, tuple(cars), _int(body, "trial", 0, MAX_SEQ))


def _decode_start(body: dict, seq: int, stamp: float) -> StartMessage:
    _only(body, {"cars", "trial"})
    trial = _int(body, "trial", 1, MAX_SEQ)
    cars = body.get("cars")
    if not isinstance(cars, dict):
        raise MessageError("start.cars must be a map")
    departures = {}
    for car, entry in cars.items():
        if isinstance(car, bool) or not isinstance(car, int) or not 1 <= car <= 255:
            raise MessageError(f"start.cars: bad car id {car!r}")
        if not isinstance(entry, dict):
            raise MessageError(f"start.cars[{car}] must be a map")
        _only(entry, {"depart", "cruise"}, common=False)
        departures[car] = (_float(entry, "depart"), _float(entry, "cruise", 1e-3, 10.0))
    return StartMessage(seq, stamp, trial, departures)


def _decode_plan(body: dict, sender: int, seq: int, stamp: float) -> PlanMessage:
    _only(body, {"t0", "dt", "pos", "vel", "goal"}, optional=frozenset({"stuck", "deadlocks"}))
    t0 = _float(body, "t0")
    dt = _float(body, "dt", low=1e-4, high=60.0)
    pos = _floats(body, "pos", 4, 2 * MAX_PLAN_STATES)
    vel = _floats(body, "vel", 4, 2 * MAX_PLAN_STATES)
    if len(pos) % 2 or len(pos) != len(vel):
        raise MessageError(f"pos and vel must hold 2N floats each, got {len(pos)} and {len(vel)}")
    goal = _floats(body, "goal", 2, 2)
    plan = Plan(t0=t0, dt=dt, positions=np.array(pos).reshape(-1, 2), velocities=np.array(vel).reshape(-1, 2))
    stuck = _bool(body, "stuck") if "stuck" in body else False
    deadlocks = _int(body, "deadlocks", 0, MAX_DEADLOCKS) if "deadlocks" in body else 0
    return PlanMessage(sender, seq, stamp, plan, (goal[0], goal[1]), stuck, deadlocks)


def _decode_trust(body: dict, sender: int, seq: int, stamp: float) -> TrustReport:
    _only(body, {"peers"})
    peers_raw = body.get("peers")
    if not isinstance(peers_raw, dict):
        raise MessageError("trust.peers must be a map")
    peers = {}
    for peer, entry in peers_raw.items():
        if isinstance(peer, bool) or not isinstance(peer, int) or not 1 <= peer <= 255:
            raise MessageError(f"trust.peers: bad peer id {peer!r}")
        if not isinstance(entry, dict):
            raise MessageError(f"trust.peers[{peer}] must be a map")
        _only(entry, {"a", "b", "tau", "trust", "eps"}, common=False)
        alpha = _floats(entry, "a", 3, 3, low=0.0, high=1e9)
        beta = _floats(entry, "b", 3, 3, low=0.0, high=1e9)
        tau = _floats(entry, "tau", 3, 3, low=0.0, high=1.0)
        peers[peer] = PeerTrust(tuple(alpha), tuple(beta), tuple(tau), _float(entry, "trust", 0.0, 1.0),
                                _float(entry, "eps", 1e-6, 100.0))
    return TrustReport(sender, seq, stamp, peers)


def _decode_status(body: dict, sender: int, seq: int, stamp: float) -> StatusMessage:
    _only(body, {"state", "replan_ms", "iterations", "at_goal", "counters", "trial"})
    counters_raw = body.get("counters")
    if not isinstance(counters_raw, dict) or len(counters_raw) > 64:
        raise MessageError("status.counters must be a map of at most 64 entries")
    counters = {}
    for name, value in counters_raw.items():
        if not isinstance(name, str) or len(name) > 64:
            raise MessageError(f"status.counters: bad name {name!r}")
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_SEQ:
            raise MessageError(f"status.counters[{name}]: expected a count, got {value!r}")
        counters[name] = value
    return StatusMessage(sender, seq, stamp, _str(body, "state", 32), _float(body, "replan_ms", 0.0, 1e7),
                         _int(body, "iterations", 0, 2**31), _bool(body, "at_goal"), counters,
                         _int(body, "trial", 0, MAX_SEQ))


# --- the receiving side's state: sender check, order and replay -------------------------------


RECENT_PAYLOADS = 8
"""Accepted payloads kept per sender, to know an identical copy without decoding it."""


class Inbox:
    """Accepts decoded messages in order per (sender, kind); counts every drop by reason.

    A sequence number at or below the last accepted one from the same sender and kind is
    a replay or arrived out of order, and is dropped -- unless the sender restarted: a
    sequence that starts over (seq < last) with a stamp later than ``restart_after_s``
    past the last accepted message is accepted as a new session.

    A payload identical to one of the last ``RECENT_PAYLOADS`` accepted from the same
    sender is not decoded again: it is the same message, judged the same way (a new plan
    goes out both best effort and reliably, so every car gets most plans twice).
    """

    def __init__(self, restart_after_s: float = 2.0):
        self.restart_after_s = restart_after_s
        self._last: dict[tuple[int, str], tuple[int, float]] = {}
        self._recent: dict[int, deque[tuple[bytes, Message]]] = {}
        self.accepted = Counter()
        self.dropped = Counter()

    def accept(self, payload: bytes, key_sender: int | None = None) -> Message | None:
        """Decode and filter one payload; None (and a counted reason) if it is dropped."""
        if isinstance(payload, (bytes, bytearray, memoryview)) and len(payload) > MAX_MESSAGE_BYTES:
            self.dropped["oversized"] += 1
            return None
        recent = self._recent.get(key_sender) if key_sender is not None else None
        for seen, message in recent or ():
            if seen == payload:
                return self._in_order(message)
        try:
            message = decode(payload)
        except MessageError:
            self.dropped["invalid"] += 1
            return None
        if key_sender is not None and message.sender != key_sender:
            self.dropped["spoofed_sender"] += 1
            return None
        if self._in_order(message) is None:
            return None
        if key_sender is not None:
            self._recent.setdefault(key_sender, deque(maxlen=RECENT_PAYLOADS)).append((bytes(payload), message))
        return message

    def _in_order(self, message: Message) -> Message | None:
        slot = (message.sender, message.kind)
        last = self._last.get(slot)
        if last is not None:
            last_seq, last_stamp = last
            restarted = message.seq < last_seq and message.stamp > last_stamp + self.restart_after_s
            if message.seq <= last_seq and not restarted:
                self.dropped["replayed" if message.seq == last_seq else "out_of_order"] += 1
                return None
        self._last[slot] = (message.seq, message.stamp)
        self.accepted[message.kind] += 1
        return message


def to_dict(message: Message) -> dict[str, Any]:
    """A JSON-ready view of a decoded message (for recordings and dashboards)."""
    out: dict[str, Any] = {"kind": message.kind, "id": message.sender, "seq": message.seq,
                           "stamp": message.stamp}
    if isinstance(message, PlanMessage):
        out.update(t0=message.plan.t0, dt=message.plan.dt, goal=list(message.goal),
                   positions=np.asarray(message.plan.positions).tolist(),
                   velocities=np.asarray(message.plan.velocities).tolist())
        if message.stuck:
            out["stuck"] = True
        if message.deadlocks:
            out["deadlocks"] = message.deadlocks
    elif isinstance(message, TrustReport):
        out["peers"] = {str(peer): {"alpha": list(pt.alpha), "beta": list(pt.beta), "tau": list(pt.tau),
                                    "trust": pt.trust, "epsilon": pt.epsilon}
                        for peer, pt in message.peers.items()}
    elif isinstance(message, PoseMessage):
        out.update(x=message.x, y=message.y, yaw=message.yaw, valid=message.valid)
    elif isinstance(message, StatusMessage):
        out.update(state=message.state, replan_ms=message.replan_ms, iterations=message.iterations,
                   at_goal=message.at_goal, counters=dict(message.counters), trial=message.trial)
    elif isinstance(message, StartMessage):
        out["trial"] = message.trial
        out["cars"] = {str(car): {"depart": d, "cruise": c} for car, (d, c) in message.departures.items()}
    elif isinstance(message, StopMessage):
        out.update(action=message.action, cars=list(message.cars), trial=message.trial)
    return out


def from_dict(data: dict[str, Any]) -> Message:
    """The inverse of to_dict (recordings are read back through this); MessageError if
    the data does not make a valid message -- it is re-encoded and decoded, so a
    recording goes through exactly the checks a live message does."""
    try:
        kind, sender, seq, stamp = data["kind"], data["id"], data["seq"], data["stamp"]
        if kind == "plan":
            message: Message = PlanMessage(sender, seq, stamp, Plan(data["t0"], data["dt"], np.array(data["positions"], dtype=float),
                                                                    np.array(data["velocities"], dtype=float)),
                                           tuple(data["goal"]), data.get("stuck", False), data.get("deadlocks", 0))
        elif kind == "trust":
            message = TrustReport(sender, seq, stamp, {
                int(peer): PeerTrust(tuple(p["alpha"]), tuple(p["beta"]), tuple(p["tau"]), p["trust"], p["epsilon"])
                for peer, p in data["peers"].items()})
        elif kind == "pose":
            message = PoseMessage(sender, seq, stamp, data["x"], data["y"], data["yaw"], data["valid"])
        elif kind == "status":
            message = StatusMessage(sender, seq, stamp, data["state"], data["replan_ms"], data["iterations"],
                                    data["at_goal"], dict(data["counters"]), data["trial"])
        elif kind == "clock":
            message = ClockMessage(sender, seq, stamp)
        elif kind == "start":
            message = StartMessage(seq, stamp, data["trial"],
                                   {int(car): (c["depart"], c["cruise"]) for car, c in data["cars"].items()})
        elif kind == "stop":
            message = StopMessage(seq, stamp, data["action"], tuple(data["cars"]), data["trial"])
        elif kind == "heartbeat":
            message = HeartbeatMessage(seq, stamp)
        else:
            raise MessageError(f"unknown message kind {kind!r}")
        return decode(encode(message))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, MessageError):
            raise
        raise MessageError(f"not a recorded message: {type(exc).__name__}: {exc}") from None
