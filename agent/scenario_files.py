"""Scenario files: TOML text <-> a validated Scenario, strictly; shipped scenes by name.

A scenario file's tables map onto the dataclasses of trustfg.agent.config; anything a
file leaves out keeps its default. A file with an unknown key, a value of the wrong type
or an out-of-range value is refused with a :class:`ConfigError` naming the file and the
key, e.g. ``planner.support_states: expected an integer, got 'many'``.

``load_scenario(SOURCE)`` takes a path, or the name of a config that ships with trustfg
(package data of ``trustfg.deploy``): ``intersection`` or ``scenarios/intersection.toml``
is a scene, ``lab/fleet`` a lab fleet config. An existing file always wins over a name.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any

from .config import ConfigError, Scenario, VehicleConfig

SHIPPED_PACKAGE = "trustfg.deploy"


def shipped(folder: str = "scenarios") -> list[str]:
    """Names of the configs that ship in ``folder`` of trustfg.deploy, sorted."""
    from importlib import resources  # only here: trustfg stop reads its config before anything else loads

    root = resources.files(SHIPPED_PACKAGE) / folder
    return sorted(entry.name[:-len(".toml")] for entry in root.iterdir() if entry.name.endswith(".toml"))


def read_source(source: str | Path) -> tuple[str, str]:
    """(TOML text, a label for errors) of a file path or a shipped config's name."""
    path = Path(source)
    if path.is_file():
        return path.read_text(encoding="utf-8"), str(path)
    name = str(source)
    stem = name[:-len(".toml")] if name.endswith(".toml") else name
    candidates = [stem] if "/" in stem else [f"scenarios/{stem}", stem]
    from importlib import resources

    root = resources.files(SHIPPED_PACKAGE)
    for candidate in candidates:
        entry = root.joinpath(*f"{candidate}.toml".split("/"))
        if entry.is_file():
            return entry.read_text(encoding="utf-8"), f"{candidate}.toml (shipped)"
    raise ConfigError(f"{source}: no such file, nor a shipped scenario (shipped: {', '.join(shipped())})")


def load_scenario(source: str | Path) -> Scenario:
    """Read a scenario from a TOML file or a shipped config's name; raise ConfigError
    naming the file and the bad key."""
    text, label = read_source(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{label}: not valid TOML: {exc}") from None
    try:
        return scenario_from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{label}: {exc}") from None


def load_vehicle(source: str | Path) -> VehicleConfig:
    """The [vehicle] table of a TOML file (what ``trustfg calibrate`` writes for one car);
    raise ConfigError naming the file and the bad key."""
    text, label = read_source(source)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{label}: not valid TOML: {exc}") from None
    if "vehicle" not in data:
        raise ConfigError(f"{label}: no [vehicle] table")
    try:
        vehicle = from_dict(VehicleConfig, data["vehicle"], "vehicle")
        vehicle.validate("vehicle")
    except ConfigError as exc:
        raise ConfigError(f"{label}: {exc}") from None
    return vehicle


def scenario_from_dict(data: dict[str, Any]) -> Scenario:
    scenario = from_dict(Scenario, data, "")
    scenario.validate()
    return scenario


def from_dict(cls: type, data: Any, path: str) -> Any:
    """Build dataclass ``cls`` from plain TOML data, strictly (unknown keys refused)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{path or 'top level'}: expected a table, got {_describe(data)}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{_join(path, unknown[0])}: unknown key (known: {', '.join(sorted(fields))})")
    kwargs = {}
    for name, f in fields.items():
        key_path = _join(path, name)
        if name in data:
            kwargs[name] = _convert(hints[name], data[name], key_path)
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{key_path}: missing required key")
    return cls(**kwargs)


def _convert(tp: Any, value: Any, path: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        return _convert(inner[0], value, path)
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, path)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{path}: expected a number, got {_describe(value)}")
        if not math.isfinite(value):
            raise ConfigError(f"{path}: expected a finite number, got {value}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{path}: expected an integer, got {_describe(value)}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{path}: expected true or false, got {_describe(value)}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{path}: expected a string, got {_describe(value)}")
        return value
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{path}: expected a table, got {_describe(value)}")
        return {_convert(args[0], k, path): _convert(args[1], v, f"{path}.{k}") for k, v in value.items()}
    if origin is tuple:
        if not isinstance(value, list):
            raise ConfigError(f"{path}: expected an array, got {_describe(value)}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise ConfigError(f"{path}: expected {len(args)} values, got {len(value)}")
        return tuple(_convert(a, v, f"{path}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
    raise ConfigError(f"{path}: unsupported config type {tp!r}")  # a bug in this module


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def dump_scenario(scenario: Scenario, changed_only: bool = False) -> str:
    """TOML text that load_scenario reads back into an equal Scenario.

    ``changed_only`` leaves out every value equal to its default (and tables left empty),
    so a scene file does not freeze today's defaults of everything else."""
    lines: list[str] = []
    top = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(scenario)}
    defaults = Scenario(name="", cars=())
    for name, value in top.items():
        if not dataclasses.is_dataclass(value) and name != "cars":
            if not (changed_only and name != "name" and value == getattr(defaults, name)):
                lines.append(f"{name} = {_toml_value(value)}")
    for name, value in top.items():
        if dataclasses.is_dataclass(value):
            fields = _fields(value, type(value)() if changed_only and name != "world" else None)
            if fields or not changed_only:
                lines.append(f"\n[{name}]")
                lines.extend(f"{k} = {_toml_value(v)}" for k, v in fields.items())
    for car in scenario.cars:
        lines.append("\n[[cars]]")
        default_car = type(car)(id=car.id, start=car.start, goal=car.goal) if changed_only else None
        lines.extend(f"{k} = {_toml_value(v)}" for k, v in _fields(car, default_car).items())
    return "\n".join(lines) + "\n"


def _fields(obj: Any, defaults: Any = None) -> dict[str, Any]:
    """The fields of ``obj`` that are set (not None) and, given ``defaults``, differ from it."""
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)
            if getattr(obj, f.name) is not None
            and (defaults is None or f.name in ("id", "start", "goal", "kind")
                 or getattr(obj, f.name) != getattr(defaults, f.name))}


def _has_defaults(obj: Any) -> bool:
    """Whether every field of dataclass ``obj`` has a default (AttackConfig's name has none)."""
    return all(f.default is not dataclasses.MISSING or f.default_factory is not dataclasses.MISSING
               for f in dataclasses.fields(obj))


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, (tuple, list)):
        if value and all(dataclasses.is_dataclass(v) for v in value):  # e.g. obstacles: one a line
            return "[\n" + "".join(f"  {_toml_value(v)},\n" for v in value) + "]"
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml_value(v)}" for k, v in value.items()) + " }"
    if dataclasses.is_dataclass(value):  # inline tables: what differs from the defaults, if it has them
        fields = _fields(value, type(value)() if _has_defaults(value) else None)
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in fields.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} to TOML")
