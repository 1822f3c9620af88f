"""What every config section shares: the error type and the checks of a value."""

from __future__ import annotations

import dataclasses
from typing import Any


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


def with_overrides(obj: Any, **changes: Any) -> Any:
    """A copy of a config dataclass with some fields replaced, validated again."""
    new = dataclasses.replace(obj, **changes)
    if hasattr(new, "validate"):
        new.validate(type(new).__name__)
    return new


def parse_udp_address(text: str, path: str = "address") -> tuple[str, int]:
    """``udp://HOST:PORT`` -> (host, port); ConfigError otherwise."""
    if not text.startswith("udp://"):
        raise ConfigError(f"{path}: expected udp://HOST:PORT, got {text!r}")
    host, _, port = text[len("udp://"):].rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"{path}: expected udp://HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


def positive(value: float, path: str) -> None:
    if not value > 0:
        raise ConfigError(f"{path}: must be > 0, got {value}")


def parse_id_values(texts: list[str] | tuple[str, ...], option: str) -> dict[int, float]:
    """``["2=0.3", ...]`` (car id = number, from a command line) -> {2: 0.3, ...}."""
    out = {}
    for text in texts:
        car, sep, value = text.partition("=")
        try:
            out[int(car)] = float(value)
        except ValueError:
            raise ConfigError(f"{option} {text!r}: expected ID=NUMBER") from None
        if not sep:
            raise ConfigError(f"{option} {text!r}: expected ID=NUMBER")
    return out
