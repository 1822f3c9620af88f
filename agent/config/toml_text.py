"""Config values and whole scenarios as TOML text, written by tomli-w.

``effective_toml(scenario)`` is what ``trustfg config show`` prints: every key of every
table with the value a run uses, which agent.scenario_files reads back into an equal
Scenario. TOML has no null, so a key whose value is None (not set) is left out and named
in a comment instead. ``value_toml`` writes one value as a key's default in the reference.
"""

from __future__ import annotations

import dataclasses
import textwrap
from typing import Any

import tomli_w


def plain_data(value: Any) -> Any:
    """A config value as TOML data: a dataclass becomes a table (its fields that are None
    left out), a tuple an array."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain_data(getattr(value, f.name)) for f in dataclasses.fields(value)
                if getattr(value, f.name) is not None}
    if isinstance(value, (tuple, list)):
        return [plain_data(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain_data(v) for k, v in value.items()}
    return value


def toml_document(table: dict[str, Any]) -> str:
    """TOML text of ``table`` (tomli-w), with every array on one line as scene files write them."""
    return _arrays_on_one_line(tomli_w.dumps(table, indent=0))


def value_toml(value: Any) -> str:
    """One value as TOML writes it after ``key = `` (``[-2.5, -2.5, 2.5, 2.5]``, ``0.001``,
    ``"peer"``, ``true``)."""
    data = plain_data(value)
    if isinstance(data, dict):  # tomli-w writes a mapping as a table of its own, not after a key
        if data:
            raise TypeError(f"no one-line TOML for a non-empty table: {data!r}")
        return "{}"
    return toml_document({"v": data})[len("v = "):].rstrip("\n")


def effective_toml(scenario: Any, source: str) -> str:
    """The whole configuration a run of ``scenario`` (read from ``source``) uses, as TOML:
    top-level keys, then every table, then the cars."""
    data = plain_data(scenario)
    data["cars"] = data.pop("cars")  # after the tables, as scene files have them
    unset = textwrap.fill("Not set, so left out (TOML has no null): " + (", ".join(unset_keys(scenario)) or "none")
                          + ".", width=96, initial_indent="# ", subsequent_indent="#   ", break_on_hyphens=False)
    return (f"# The effective configuration of {source}: trustfg's defaults, then the file; every key.\n{unset}\n"
            "# What each key does: trustfg config reference (docs/configuration.md).\n\n" + toml_document(data))


def unset_keys(scenario: Any) -> list[str]:
    """The keys of ``scenario`` whose value is None, as ``sim.replan_phase_max_s``,
    ``cars.attack (cars 1, 2)`` or ``cars.attack (every car)``."""
    out = []
    for f in dataclasses.fields(scenario):
        section = getattr(scenario, f.name)
        if dataclasses.is_dataclass(section):
            out.extend(f"{f.name}.{g.name}" for g in dataclasses.fields(section) if getattr(section, g.name) is None)
    for g in dataclasses.fields(scenario.cars[0]) if scenario.cars else ():
        ids = [str(car.id) for car in scenario.cars if getattr(car, g.name) is None]
        if len(ids) == len(scenario.cars):
            out.append(f"cars.{g.name} (every car)")
        elif ids:
            out.append(f"cars.{g.name} (car{'s' if len(ids) > 1 else ''} {', '.join(ids)})")
    return out


def _arrays_on_one_line(text: str) -> str:
    """Join the items tomli-w writes one a line (at indent 0). Only inside an array does a
    line of its output end in "[" or ",": a key's line ends in its value's last character
    (a digit, a letter of true/false/inf/nan, a quote, "}" or "]"), a header in "]", and a
    string escapes its newlines (multi-line strings are off)."""
    return text.replace("[\n", "[").replace(",\n]", "]").replace(",\n", ", ")
