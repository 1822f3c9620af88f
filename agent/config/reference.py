"""The reference of the scenario TOML, generated from the config dataclasses themselves.

Every table a scenario file may hold and every key in it, as agent.scenario_files reads
them: one table per dataclass field of Scenario, ``[[cars]]`` an array of tables, obstacles
and a car's attack tables inside them, no aliases. Per key: its type as TOML names it, its
unit (from the name's suffix, ``_mps`` is m/s, else from an "in UNIT" of its docstring),
its default as TOML writes it, and its meaning: the first paragraph of its attribute
docstring (the string literal after the field, in the class that declares it), read from
the package's own source with ast. ``render()`` is the page docs/configuration.md, which
``trustfg config reference`` writes.
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import inspect
import re
import sys
import types
import typing
from dataclasses import dataclass
from typing import Any

from . import Scenario, attacks
from .attacks import ATTACKS, AttackConfig
from .scene import CarConfig
from .toml_text import value_toml

REQUIRED = "required"
"""The default of a key a file must set."""
NOT_SET = "not set"
"""The default of a key whose value is None unless a file sets it."""
REGENERATE = "trustfg config reference --out docs/configuration.md"
"""The command that writes the page."""

SUFFIX_UNITS = (("_radps2", "rad/s^2"), ("_radps", "rad/s"), ("_mps2", "m/s^2"), ("_mps", "m/s"), ("_ms", "ms"),
                ("_hz", "Hz"), ("_deg", "degrees"), ("_rad", "rad"), ("_m", "m"), ("_s", "s"))
"""A key's unit from the end of its name, longest suffix first."""
_DOC_UNIT = re.compile(r"\bin (m\^2/s\^3|m/s\^2|rad/s\^2|m/s|rad/s|1/m\^2|1/m|1/s|ms|Hz|m|s)(?=[\s.,;:)]|$)")


@dataclass(frozen=True)
class Key:
    """One key of a table."""

    name: str
    type: str
    """As a TOML user reads it: float, integer, string, boolean, array of ..., table."""
    unit: str
    """Empty when the value has none."""
    default: str
    """TOML text of the default, REQUIRED, NOT_SET, or empty for a table of its own."""
    meaning: str
    section: str = ""
    """Path of the section a table-valued key opens (``world``, ``cars.attack``); else empty."""


@dataclass(frozen=True)
class Section:
    """One table of a scenario file."""

    path: str
    """Dotted TOML path: ``planner``, ``cars``, ``world.obstacles``; empty at the top level."""
    title: str
    """How a file writes it: ``[planner]``, ``[[cars]]``, ``params`` of ``bias``."""
    cls: type
    """The dataclass it maps onto."""
    about: tuple[str, ...]
    """Paragraphs that say what the table is; a paragraph of indented lines is verbatim text."""
    keys: tuple[Key, ...]
    per_car: tuple[Key, ...] = ()
    """Keys of a ``[[cars]]`` entry that set this table's key of the same name for that car."""
    depth: int = 1


def sections() -> tuple[Section, ...]:
    """Every table of a scenario file, in reading order: the top level, then each table
    followed by the tables inside it."""
    found: list[Section] = []
    _walk(Scenario, "", "Top level", 1, found)
    return tuple(found)


def _walk(cls: type, path: str, title: str, depth: int, found: list[Section], about: tuple[str, ...] = ()) -> None:
    hints = typing.get_type_hints(cls)
    docs = field_docs(cls)
    keys, nested = [], []
    for f in dataclasses.fields(cls):
        table = _table_class(hints[f.name])
        child = "" if table is None else (f"{path}.{f.name}" if path else f.name)
        if table is not None:  # a top-level table has a header of its own, a nested one is named by its path
            is_array = typing.get_origin(_without_none(hints[f.name])) is tuple
            nested.append((child, table, child if path else (f"[[{child}]]" if is_array else f"[{child}]")))
        keys.append(_key(f, hints, docs, child))
    found.append(Section(path=path, title=title, cls=cls, about=about or paragraphs(cls.__doc__ or ""),
                         keys=tuple(keys), per_car=_per_car(cls, path), depth=depth))
    for child, table, child_title in nested:
        child_depth = depth + 1 if path else depth  # the top level's tables are its peers on the page
        if table is AttackConfig:
            _walk_attack(child, child_title, child_depth, found)
        else:
            _walk(table, child, child_title, child_depth, found)


def _table_class(tp: Any) -> type | None:
    """The dataclass of a field that is a table (``[planner]``, ``attack``) or an array of
    tables (``[[cars]]``, ``obstacles``); None for a plain value."""
    tp = _without_none(tp)
    if dataclasses.is_dataclass(tp):
        return tp
    args = typing.get_args(tp)
    if typing.get_origin(tp) is tuple and args and dataclasses.is_dataclass(args[0]):
        return args[0]
    return None


def _walk_attack(path: str, title: str, depth: int, found: list[Section]) -> None:
    """The attack table, and the parameters of each attack: ``params`` is a table of
    numbers whose keys are the named attacks' fields (agent.config.attacks)."""
    about = paragraphs(AttackConfig.__doc__ or "") + paragraphs(attacks.__doc__ or "")[1:]
    _walk(AttackConfig, path, title, depth, found, about)
    for name, cls in ATTACKS.items():
        _walk(cls, f"{path}.params", f"`params` of `{name}`", depth + 1, found)


def _per_car(cls: type, path: str) -> tuple[Key, ...]:
    """Keys of a car's table named like keys of this (fleet-wide) table."""
    if path in ("", "cars") or path.startswith("cars."):
        return ()
    names = {f.name for f in dataclasses.fields(cls)}
    hints, docs = typing.get_type_hints(CarConfig), field_docs(CarConfig)
    return tuple(_key(f, hints, docs) for f in dataclasses.fields(CarConfig) if f.name in names)


def _key(f: dataclasses.Field, hints: dict[str, Any], docs: dict[str, str], section: str = "") -> Key:
    doc = docs.get(f.name, "")
    return Key(name=f.name, type=toml_type(hints[f.name]), unit=unit_of(f.name, doc), default=default_of(f),
               meaning=first_paragraph(doc), section=section)


# --- what a field says about itself ------------------------------------------------------------


def field_docs(cls: type) -> dict[str, str]:
    """Attribute docstrings of the dataclass ``cls``, inherited ones included (a subclass's
    own wins), by field name."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if dataclasses.is_dataclass(klass):
            docs.update(_own_field_docs(klass))
    return docs


@functools.cache
def _own_field_docs(cls: type) -> dict[str, str]:
    """The string literal right after each annotated name in the body of ``cls``'s class
    statement, from its module's source."""
    tree = _module_tree(cls.__module__)
    node = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls.__name__)
    out = {}
    for here, after in zip(node.body, node.body[1:]):
        if (isinstance(here, ast.AnnAssign) and isinstance(here.target, ast.Name) and isinstance(after, ast.Expr)
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
            out[here.target.id] = inspect.cleandoc(after.value.value)
    return out


@functools.cache
def _module_tree(module: str) -> ast.Module:
    return ast.parse(inspect.getsource(sys.modules[module]))


def paragraphs(doc: str) -> tuple[str, ...]:
    """A docstring's paragraphs in plain text; one whose lines are all indented is kept as
    it stands (dedented), for formulas and examples."""
    out = []
    for block in re.split(r"\n\s*\n", inspect.cleandoc(doc)):
        lines = block.splitlines()
        if lines and all(line.startswith(" ") for line in lines):
            out.append("\n".join("    " + line for line in inspect.cleandoc("\n".join(lines)).splitlines()))
        elif block.strip():
            text = plain_text(block)
            out.append(text[:-1] if text.endswith("::") else text)
    return tuple(out)


def first_paragraph(doc: str) -> str:
    return plain_text(re.split(r"\n\s*\n", doc.strip())[0]) if doc.strip() else ""


def plain_text(text: str) -> str:
    """reStructuredText markup (``x``, :class:`y`, `z`) dropped, lines joined."""
    text = re.sub(r":[a-z]+:`~?\.?([^`]+)`", r"\1", text)
    text = re.sub(r"``(.+?)``", r"\1", text, flags=re.S)
    text = re.sub(r"`([^`]+)`", r"\1", text)
    return " ".join(text.split())


def unit_of(name: str, doc: str) -> str:
    """The unit of key ``name``: its suffix's, else the first "in UNIT" of the first
    paragraph of its docstring; empty when neither names one."""
    for suffix, unit in SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit
    found = _DOC_UNIT.search(first_paragraph(doc))
    return found.group(1) if found else ""


def toml_type(tp: Any) -> str:
    """A field's type as TOML names it: ``float``, ``array of 2 floats``, ``table``."""
    tp = _without_none(tp)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"array of {_plural(args[0])}"
        if len(set(args)) == 1:
            return f"array of {len(args)} {_plural(args[0])}"
        return "array of " + ", ".join(toml_type(a) for a in args)
    if origin is dict:
        return f"table of {_plural(args[1])}"
    if dataclasses.is_dataclass(tp):
        return "table"
    return {float: "float", int: "integer", str: "string", bool: "boolean"}[tp]


def _plural(tp: Any) -> str:
    text = toml_type(tp)
    if text.startswith("array of"):
        return "arrays" + text[len("array"):]
    return text + "s"


def _without_none(tp: Any) -> Any:
    """``X | None`` -> X (TOML has no null: a file sets X or leaves the key out)."""
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        return next(a for a in typing.get_args(tp) if a is not type(None))
    return tp


def default_of(f: dataclasses.Field) -> str:
    if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
        return REQUIRED
    value = f.default if f.default is not dataclasses.MISSING else f.default_factory()
    if value is None:
        return NOT_SET
    if dataclasses.is_dataclass(value):
        return ""
    return value_toml(value)


# --- the page ----------------------------------------------------------------------------------

INTRO = f"""\
# Configuration reference

A scenario file is TOML: the cars of a fleet on a map, and whatever else a run needs
(the scenes in `deploy/scenarios/`, the lab fleets in `deploy/lab/`). Every value comes
from three layers, each over the one before:

1. trustfg's shipped defaults: the Default column below;
2. the file: a key it sets replaces the default, a key it leaves out keeps it;
3. command-line overrides of a few keys for one run, e.g. `trustfg sim --laps 3` sets
   `control.laps` and `--deadman 1` sets `operator.deadman_s`.

`trustfg config show --scenario FILE|NAME` prints the first two merged: every key with the
value a run of that file uses.

A file is read strictly. An unknown key, a value of the wrong type or out of range is
refused with an error naming the file and the key, e.g. `planner.support_states: expected
an integer, got 'many'`; a key marked required must be there. A float key takes an integer
too (`1` reads as `1.0`); nothing else is converted. TOML has no null: a key whose default
is "not set" is set by giving it a value and left unset by leaving it out.

The tables are fleet-wide: every car runs the same `[planner]`, `[trust]` and so on. What
differs per car is in its `[[cars]]` entry; where one of its keys sets a table's key for
that car, the table says so.

This page is generated from the source (`agent/config/`): regenerate it with
`{REGENERATE}`.
"""


def render() -> str:
    """The Markdown page: the introduction, then a table of keys per section."""
    out = [INTRO]
    for section in sections():
        out.append(f"\n{'#' * (section.depth + 1)} {heading(section)}\n")
        for paragraph in section.about:
            out.append(f"\n```text\n{_dedent(paragraph)}\n```\n" if paragraph.startswith("    ") else f"\n{paragraph}\n")
        out.append("")
        out.append(_table(section.keys, section.path) if section.keys else "It has no parameters.\n")
        if section.per_car:
            out.append("A `[[cars]]` entry may set, for its car: "
                       + "; ".join(f"`{k.name}`: {_cell(k.meaning)}" for k in section.per_car) + "\n")
    return "\n".join(out).replace("\n\n\n", "\n\n")


def heading(section: Section) -> str:
    """The text of a section's heading on the page."""
    return section.title if section.title.startswith(("Top", "`")) else f"`{section.title}`"


def _table(keys: tuple[Key, ...], path: str) -> str:
    rows = ["| Key | Type | Unit | Default | Meaning |", "| --- | --- | --- | --- | --- |"]
    for key in keys:
        default = key.default if key.default in (REQUIRED, NOT_SET, "") else f"`{_cell(key.default)}`"
        meaning = _cell(key.meaning)
        if key.section:
            title = _section_title(key, path)
            meaning += f" See [`{title}`](#{anchor(title)})."
        rows.append(f"| `{key.name}` | {key.type} | {key.unit} | {default or '-'} | {meaning} |")
    return "\n".join(rows) + "\n"


def _section_title(key: Key, path: str) -> str:
    if path:
        return key.section
    return f"[[{key.section}]]" if key.type.startswith("array") else f"[{key.section}]"


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _dedent(text: str) -> str:
    return "\n".join(line[4:] for line in text.splitlines())
