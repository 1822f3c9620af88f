"""Checked reads of a decoded msgpack map's fields (agent.messages uses them).

Each function returns the field's value or raises :class:`MessageError` naming the field
and what was wrong (type, range, length, a non-finite number) -- never another exception.
"""

from __future__ import annotations

import math


class MessageError(ValueError):
    """A payload is not a valid trustfg message."""


def only(body: dict, allowed: set[str], common: bool = True, optional: frozenset[str] = frozenset()) -> None:
    """Every key of ``allowed`` (and the common keys) present, ``optional`` ones may be,
    nothing else."""
    expected = allowed | ({"v", "k", "id", "seq", "t"} if common else set())
    extra = set(body) - expected - optional
    if extra:
        raise MessageError(f"unexpected field(s) {sorted(map(str, extra))}")
    missing = expected - set(body)
    if missing:
        raise MessageError(f"missing field(s) {sorted(missing)}")


def integer(body: dict, key: str, low: int, high: int) -> int:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"{key}: expected an integer, got {type(value).__name__}")
    if not low <= value <= high:
        raise MessageError(f"{key}: {value} outside [{low}, {high}]")
    return value


def number(body: dict, key: str, low: float = -1e12, high: float = 1e12) -> float:
    value = body.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise MessageError(f"{key}: expected a number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise MessageError(f"{key}: not finite")
    if not low <= value <= high:
        raise MessageError(f"{key}: {value} outside [{low}, {high}]")
    return value


def numbers(body: dict, key: str, min_len: int, max_len: int,
            low: float = -1e6, high: float = 1e6) -> list[float]:
    value = body.get(key)
    if not isinstance(value, list):
        raise MessageError(f"{key}: expected an array, got {type(value).__name__}")
    if not min_len <= len(value) <= max_len:
        raise MessageError(f"{key}: length {len(value)} outside [{min_len}, {max_len}]")
    if value and all(type(x) is float for x in value) and math.isfinite(sum(value)) \
            and low <= min(value) and max(value) <= high:
        return list(value)  # the common case at a few calls per array: every one a finite float in range
    out = []
    for x in value:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            raise MessageError(f"{key}: expected numbers, got {type(x).__name__}")
        x = float(x)
        if not math.isfinite(x) or not low <= x <= high:
            raise MessageError(f"{key}: value {x} not finite or outside [{low}, {high}]")
        out.append(x)
    return out


def string(body: dict, key: str, max_len: int) -> str:
    value = body.get(key)
    if not isinstance(value, str) or not 0 < len(value) <= max_len:
        raise MessageError(f"{key}: expected a string of 1..{max_len} characters")
    return value


def boolean(body: dict, key: str) -> bool:
    value = body.get(key)
    if not isinstance(value, bool):
        raise MessageError(f"{key}: expected true or false, got {type(value).__name__}")
    return value
