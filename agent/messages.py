"""Fleet messages: msgpack maps with a schema version, validated field by field.

Every message is a msgpack map with these common keys:

    v     int    schema version (SCHEMA_VERSION)
    k     str    kind: "plan" | "trust" | "pose" | "status" | "start"
    id    int    sender car id, 1..255 (must match N in the key trustfg/F/N/...);
                 0 for the operator's "start" (key trustfg/F/start)
    seq   int    sender's sequence number for this kind, 0..2^53
    t     float  stamp, seconds on the fleet clock

and per kind:

    plan    t0 float, dt float > 0, pos [x0, y0, x1, y1, ...] (2N floats, 2 <= N <= 256),
            vel [...] (2N floats), goal [x, y]
    trust   peers {peer_id: {a: [3 floats >= 0], b: [3 floats >= 0], tau: [3 floats in
            [0, 1]], trust: float in [0, 1], eps: float > 0}}; a/b are the sender's DIRECT
            evidence (safety, consistency, transparency) -- testimonies never carry fused
            values, so rumours cannot loop -- tau/trust/eps are what the sender believes
            and keeps (for dashboards; receivers do not fuse them)
    pose    x, y, yaw floats, valid bool (own car, as its NatNet client sees it)
    status  state str (<= 32 chars), replan_ms float >= 0, iterations int >= 0,
            at_goal bool, counters {str: int >= 0} (<= 64 entries)
    start   cars {car_id: {depart: float, cruise: float > 0}}: when each car may set off
            (fleet clock) and at what cruise speed (m/s); sent by the operator, id 0

Decoding checks types, lengths, finiteness and a size cap (MAX_MESSAGE_BYTES) and raises
:class:`MessageError` for anything else -- never another exception. :class:`Inbox`
adds what needs state: the sender id must match the key, and messages out of order or
replayed are dropped; every drop is counted by reason.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Union

import msgpack
import numpy as np

from .gp import Plan

SCHEMA_VERSION = 1
MAX_MESSAGE_BYTES = 64 * 1024
MAX_PLAN_STATES = 256
MAX_PEERS = 255
MAX_SEQ = 2**53
DIMENSIONS = ("safety", "consistency", "transparency")


class MessageError(ValueError):
    """A payload is not a valid trustfg message."""


@dataclass(frozen=True)
class PlanMessage:
    sender: int
    seq: int
    stamp: float
    plan: Plan
    goal: tuple[float, float]

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

    kind = "status"


@dataclass(frozen=True)
class StartMessage:
    """The operator's go: departure time and cruise speed per car."""

    seq: int
    stamp: float
    departures: dict[int, tuple[float, float]] = field(default_factory=dict)

    kind = "start"
    sender = 0


Message = Union[PlanMessage, TrustReport, PoseMessage, StatusMessage, StartMessage]


# --- encoding ---------------------------------------------------------------------------------


def encode(message: Message) -> bytes:
    body: dict[str, Any] = {"v": SCHEMA_VERSION, "k": message.kind, "id": message.sender,
                            "seq": message.seq, "t": float(message.stamp)}
    if isinstance(message, PlanMessage):
        body.update(t0=float(message.plan.t0), dt=float(message.plan.dt),
                    pos=[float(x) for x in np.asarray(message.plan.positions).ravel()],
                    vel=[float(x) for x in np.asarray(message.plan.velocities).ravel()],
                    goal=[float(message.goal[0]), float(message.goal[1])])
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
                    counters={str(k): int(v) for k, v in message.counters.items()})
    elif isinstance(message, StartMessage):
        body["cars"] = {int(car): {"depart": float(depart), "cruise": float(cruise)}
                        for car, (depart, cruise) in message.departures.items()}
    else:
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
    sender = _int(body, "id", 0 if kind == "start" else 1, 0 if kind == "start" else 255)
    seq = _int(body, "seq", 0, MAX_SEQ)
    stamp = _float(body, "t")
    if kind == "start":
        _only(body, {"cars"})
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
        return StartMessage(seq, stamp, departures)
    if kind == "plan":
        _only(body, {"t0", "dt", "pos", "vel", "goal"})
        t0 = _float(body, "t0")
        dt = _float(body, "dt", low=1e-4, high=60.0)
        pos = _floats(body, "pos", 4, 2 * MAX_PLAN_STATES)
        vel = _floats(body, "vel", 4, 2 * MAX_PLAN_STATES)
        if len(pos) % 2 or len(pos) != len(vel):
            raise MessageError(f"pos and vel must hold 2N floats each, got {len(pos)} and {len(vel)}")
        goal = _floats(body, "goal", 2, 2)
        plan = Plan(t0=t0, dt=dt, positions=np.array(pos).reshape(-1, 2),
                    velocities=np.array(vel).reshape(-1, 2))
        return PlanMessage(sender, seq, stamp, plan, (goal[0], goal[1]))
    if kind == "trust":
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
            peers[peer] = PeerTrust(tuple(alpha), tuple(beta), tuple(tau),
                                    _float(entry, "trust", 0.0, 1.0),
                                    _float(entry, "eps", 1e-6, 100.0))
        return TrustReport(sender, seq, stamp, peers)
    if kind == "pose":
        _only(body, {"x", "y", "yaw", "valid"})
        return PoseMessage(sender, seq, stamp, _float(body, "x"), _float(body, "y"),
                           _float(body, "yaw"), _bool(body, "valid"))
    if kind == "status":
        _only(body, {"state", "replan_ms", "iterations", "at_goal", "counters"})
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
        return StatusMessage(sender, seq, stamp, _str(body, "state", 32),
                             _float(body, "replan_ms", 0.0, 1e7),
                             _int(body, "iterations", 0, 2**31), _bool(body, "at_goal"), counters)
    raise MessageError(f"unknown message kind {kind!r}")


def _only(body: dict, allowed: set[str], common: bool = True) -> None:
    expected = allowed | ({"v", "k", "id", "seq", "t"} if common else set())
    extra = set(body) - expected
    if extra:
        raise MessageError(f"unexpected field(s) {sorted(map(str, extra))}")
    missing = expected - set(body)
    if missing:
        raise MessageError(f"missing field(s) {sorted(missing)}")


def _int(body: dict, key: str, low: int, high: int) -> int:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"{key}: expected an integer, got {type(value).__name__}")
    if not low <= value <= high:
        raise MessageError(f"{key}: {value} outside [{low}, {high}]")
    return value


def _float(body: dict, key: str, low: float = -1e12, high: float = 1e12) -> float:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MessageError(f"{key}: expected a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise MessageError(f"{key}: not finite")
    if not low <= value <= high:
        raise MessageError(f"{key}: {value} outside [{low}, {high}]")
    return value


def _floats(body: dict, key: str, min_len: int, max_len: int,
            low: float = -1e6, high: float = 1e6) -> list[float]:
    value = body.get(key)
    if not isinstance(value, list):
        raise MessageError(f"{key}: expected an array, got {type(value).__name__}")
    if not min_len <= len(value) <= max_len:
        raise MessageError(f"{key}: length {len(value)} outside [{min_len}, {max_len}]")
    out = []
    for x in value:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise MessageError(f"{key}: expected numbers, got {type(x).__name__}")
        x = float(x)
        if not math.isfinite(x) or not low <= x <= high:
            raise MessageError(f"{key}: value {x} not finite or outside [{low}, {high}]")
        out.append(x)
    return out


def _str(body: dict, key: str, max_len: int) -> str:
    value = body.get(key)
    if not isinstance(value, str) or not 0 < len(value) <= max_len:
        raise MessageError(f"{key}: expected a string of 1..{max_len} characters")
    return value


def _bool(body: dict, key: str) -> bool:
    value = body.get(key)
    if not isinstance(value, bool):
        raise MessageError(f"{key}: expected true or false, got {type(value).__name__}")
    return value


# --- the receiving side's state: sender check, order and replay -------------------------------


class Inbox:
    """Accepts decoded messages in order per (sender, kind); counts every drop by reason.

    A sequence number at or below the last accepted one from the same sender and kind is
    a replay or arrived out of order, and is dropped -- unless the sender restarted: a
    sequence that starts over (seq < last) with a stamp later than ``restart_after_s``
    past the last accepted message is accepted as a new session.
    """

    def __init__(self, restart_after_s: float = 2.0):
        self.restart_after_s = restart_after_s
        self._last: dict[tuple[int, str], tuple[int, float]] = {}
        self.accepted = Counter()
        self.dropped = Counter()

    def accept(self, payload: bytes, key_sender: int | None = None) -> Message | None:
        """Decode and filter one payload; None (and a counted reason) if it is dropped."""
        if isinstance(payload, (bytes, bytearray, memoryview)) and len(payload) > MAX_MESSAGE_BYTES:
            self.dropped["oversized"] += 1
            return None
        try:
            message = decode(payload)
        except MessageError:
            self.dropped["invalid"] += 1
            return None
        if key_sender is not None and message.sender != key_sender:
            self.dropped["spoofed_sender"] += 1
            return None
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
    elif isinstance(message, TrustReport):
        out["peers"] = {str(peer): {"alpha": list(pt.alpha), "beta": list(pt.beta), "tau": list(pt.tau),
                                    "trust": pt.trust, "epsilon": pt.epsilon}
                        for peer, pt in message.peers.items()}
    elif isinstance(message, PoseMessage):
        out.update(x=message.x, y=message.y, yaw=message.yaw, valid=message.valid)
    elif isinstance(message, StatusMessage):
        out.update(state=message.state, replan_ms=message.replan_ms, iterations=message.iterations,
                   at_goal=message.at_goal, counters=dict(message.counters))
    elif isinstance(message, StartMessage):
        out["cars"] = {str(car): {"depart": d, "cruise": c} for car, (d, c) in message.departures.items()}
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
                                           tuple(data["goal"]))
        elif kind == "trust":
            message = TrustReport(sender, seq, stamp, {
                int(peer): PeerTrust(tuple(p["alpha"]), tuple(p["beta"]), tuple(p["tau"]), p["trust"], p["epsilon"])
                for peer, p in data["peers"].items()})
        elif kind == "pose":
            message = PoseMessage(sender, seq, stamp, data["x"], data["y"], data["yaw"], data["valid"])
        elif kind == "status":
            message = StatusMessage(sender, seq, stamp, data["state"], data["replan_ms"], data["iterations"],
                                    data["at_goal"], dict(data["counters"]))
        elif kind == "start":
            message = StartMessage(seq, stamp, {int(car): (c["depart"], c["cruise"]) for car, c in data["cars"].items()})
        else:
            raise MessageError(f"unknown message kind {kind!r}")
        return decode(encode(message))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        if isinstance(exc, MessageError):
            raise
        raise MessageError(f"not a recorded message: {type(exc).__name__}: {exc}") from None
