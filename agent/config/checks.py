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
