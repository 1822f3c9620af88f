"""The fleet's Zenoh key expressions, built and parsed here and nowhere else.

Keys (F the fleet, N the car id):

    trustfg/F/N/plan     Plan         best effort, express, every control.plan_period_s (on
                                      a UDP link where there is one), and each new plan
                                      also reliably (AdvancedPublisher, cache of 1: late
                                      joiners get the latest at once)
    trustfg/F/N/trust    TrustReport  best effort, express (each supersedes the last)
    trustfg/F/N/pose     Pose         best effort, express
    trustfg/F/N/status   Status       best effort
    trustfg/F/N/alive    liveliness token of car N's process
    trustfg/F/N/clock    car N's queryable: answers a Clock message (its clock), for
                         the operator's clock check (trustfg check)
    trustfg/F/start      Start        the operator's go for a trial (cached, late joiners
                                      get it, a missed one is recovered at the publisher's
                                      next heartbeat; a car takes it only before its departure)
    trustfg/F/stop       Stop         the operator's e-stop, release or abort (cached, recovered
                                      the same way)
    trustfg/F/heartbeat  Heartbeat    an operator's session is alive (the deadman)
    trustfg/F/truth      mocap-sim's ground truth, in recordings only (never on the bus)

Only the operator may put start, stop and heartbeat (fleet.bus.security).

Advanced publishers and subscribers (plans, the start) add Zenoh's own machinery under ``<key>/@adv/...``;
access control (fleet.bus.security) must allow it next to the keys themselves.
"""

from __future__ import annotations

ROOT = "trustfg"
KINDS = ("plan", "trust", "pose", "status")
"""What a car publishes under its own keys."""
HEARD_BY_CARS = ("plan", "trust")
"""What a car receives of its peers': its agent reads plans and trust reports only (poses
and status are for observers; subscribing a car to them would double what it decodes)."""
ALIVE = "alive"
CLOCK = "clock"
START = "start"
STOP = "stop"
HEARTBEAT = "heartbeat"
OPERATOR = (START, STOP, HEARTBEAT)
"""The operator's keys: trustfg/F/KIND, put by the operator only."""
TRUTH = "truth"


def key(fleet: str, car_id: int, kind: str) -> str:
    """A car's own key: trustfg/F/N/kind."""
    return f"{ROOT}/{fleet}/{car_id}/{kind}"


def fleet_key(fleet: str, name: str) -> str:
    """A key of the fleet as a whole: trustfg/F/start, trustfg/F/truth."""
    return f"{ROOT}/{fleet}/{name}"


def every_car(fleet: str, kind: str) -> str:
    """The pattern of one kind from every car: trustfg/F/*/kind."""
    return f"{ROOT}/{fleet}/*/{kind}"


def car_tree(fleet: str, car_id: int | str) -> list[str]:
    """Everything under a car's keys (or ``*``'s, or ``**``), its publishers' machinery too."""
    return [f"{ROOT}/{fleet}/{car_id}/**", f"{ROOT}/{fleet}/{car_id}/**/@adv/**"]


def fleet_tree(fleet: str) -> list[str]:
    """Everything of the fleet, Zenoh's machinery under it too."""
    return [f"{ROOT}/{fleet}/**", f"{ROOT}/{fleet}/**/@adv/**"]


def fleet_key_tree(fleet: str, name: str) -> list[str]:
    """A fleet key and its publisher's machinery (the start's advanced publisher)."""
    return [fleet_key(fleet, name), f"{fleet_key(fleet, name)}/@adv/**"]


def parse_key(fleet: str, key_expr: str) -> tuple[int, str] | None:
    """``trustfg/F/N/kind`` -> (N, kind); ``trustfg/F/start`` (or another of the operator's
    keys) -> (0, "start"); else None."""
    parts = key_expr.split("/")
    if len(parts) == 3 and parts[:2] == [ROOT, fleet] and parts[2] in OPERATOR:
        return 0, parts[2]
    if len(parts) != 4 or parts[:2] != [ROOT, fleet] or parts[3] not in (*KINDS, ALIVE, CLOCK):
        return None
    if not parts[2].isdigit() or not 1 <= int(parts[2]) <= 255 or parts[2] != str(int(parts[2])):
        return None
    return int(parts[2]), parts[3]
