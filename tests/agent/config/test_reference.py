"""The configuration reference: every field of every config dataclass is on the page with a
meaning, the committed page is what the generator writes now, its defaults are the
dataclasses' and its keys are what the loader accepts."""

import dataclasses
import inspect
import re
import tomllib
from pathlib import Path

import pytest

from trustfg.agent import config
from trustfg.agent.config import ConfigError, Scenario, attacks, planning, reference, running, scene
from trustfg.agent.config.reference import NOT_SET, REGENERATE, REQUIRED
from trustfg.agent.config.toml_text import plain_data
from trustfg.agent.scenario_files import from_dict

ROOT = Path(__file__).resolve().parents[3]
PAGE = ROOT / "docs" / "configuration.md"
CONFIG_MODULES = (config, attacks, planning, running, scene)


def config_dataclasses() -> list[type]:
    """Every dataclass defined in the config modules, found without the reference's walk."""
    return sorted({cls for module in CONFIG_MODULES for _, cls in inspect.getmembers(module, inspect.isclass)
                   if dataclasses.is_dataclass(cls) and cls.__module__ == module.__name__}, key=lambda c: c.__name__)


def test_every_field_of_every_config_dataclass_has_a_docstring_and_an_entry():
    undocumented = [f"{cls.__module__}.{cls.__name__}.{f.name}" for cls in config_dataclasses()
                    for f in dataclasses.fields(cls) if not reference.field_docs(cls).get(f.name, "").strip()]
    assert not undocumented, ("these fields need an attribute docstring (a string literal right after the field) "
                              "saying what the value does, its unit and its default: " + ", ".join(undocumented))
    sections = reference.sections()
    shown = {s.cls for s in sections}
    assert shown <= set(config_dataclasses())
    unshown = [cls.__name__ for cls in config_dataclasses() if not any(issubclass(s, cls) for s in shown)]
    assert not unshown, f"config dataclasses neither on the page nor a base of one that is: {unshown}"
    for section in sections:
        assert [k.name for k in section.keys] == [f.name for f in dataclasses.fields(section.cls)]
        for key in section.keys:
            assert key.meaning and key.type, f"{section.title} {key.name}"
            assert "``" not in key.meaning and ":class:" not in key.meaning, key.meaning


def test_the_committed_page_is_what_the_generator_writes_now():
    assert PAGE.read_text(encoding="utf-8") == reference.render(), (
        f"docs/configuration.md is not what the config dataclasses say now; regenerate it with `{REGENERATE}`")


def page_tables() -> list[tuple[str, dict[str, list[str]]]]:
    """(heading, {key: its row's cells}) per heading of the page, in order."""
    out = []
    for line in PAGE.read_text(encoding="utf-8").splitlines():
        if line.startswith("#") and not line.startswith("# "):
            out.append((line.lstrip("#").strip(), {}))
        elif line.startswith("| `") and out:
            cells = [cell.strip().replace("\\|", "|") for cell in re.split(r"(?<!\\)\|", line)[1:-1]]
            out[-1][1][cells[0].strip("`")] = cells
    return out


def test_the_page_shows_each_section_under_its_heading_and_the_dataclass_defaults():
    tables = page_tables()
    sections = reference.sections()
    assert [heading for heading, _ in tables] == [reference.heading(s) for s in sections]
    assert len(set(reference.anchor(h) for h, _ in tables if not h.startswith("`params`"))) == len(
        [h for h, _ in tables if not h.startswith("`params`")]), "two sections share an anchor"
    for (heading, rows), section in zip(tables, sections):
        assert list(rows) == [f.name for f in dataclasses.fields(section.cls)], heading
        for f in dataclasses.fields(section.cls):
            cell = rows[f.name][3]
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                assert cell == REQUIRED, f"{heading} {f.name}"
                continue
            default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            if default is None:
                assert cell == NOT_SET, f"{heading} {f.name}"
            elif dataclasses.is_dataclass(default):
                assert cell == "-", f"{heading} {f.name}"
            else:
                assert cell.startswith("`") and cell.endswith("`"), f"{heading} {f.name}: {cell}"
                assert tomllib.loads(f"v = {cell[1:-1]}")["v"] == plain_data(default), f"{heading} {f.name}: {cell}"


def value_of(key: reference.Key):
    """A value of the key's type: its default as the reference writes it, or one made up
    where it has none."""
    if key.default not in (REQUIRED, NOT_SET, ""):
        return tomllib.loads(f"v = {key.default}")["v"]
    return {"float": 0.5, "integer": 1, "array of 2 floats": [0.0, 1.0]}[key.type]


def table_of(section: reference.Section) -> dict:
    return {k.name: value_of(k) for k in section.keys if not k.section}


def test_every_key_of_the_reference_is_accepted_by_the_loader_where_the_reference_puts_it():
    """A file that sets every key of every table at its default (a made-up value where there
    is none), each attack with all its parameters, is read by the loader without an unknown
    key or a wrong type; a key the reference does not name is refused."""
    sections = reference.sections()
    by_path = {s.path: s for s in sections}
    data = {"name": "every-key", "fleet": "demo"}
    data.update({s.path: table_of(s) for s in sections if s.path and "." not in s.path and s.path != "cars"})
    data["world"]["obstacles"] = [table_of(by_path["world.obstacles"])]
    every_attack = [{"name": s.title.split("`")[3], "params": table_of(s)}
                    for s in sections if s.path == "cars.attack.params"]
    car = table_of(by_path["cars"])
    assert [a["name"] for a in every_attack] == list(attacks.ATTACKS)
    data["cars"] = [dict(car, id=i + 1, attack=attack) for i, attack in enumerate(every_attack)]
    scenario = from_dict(Scenario, data, "")
    assert scenario.world.obstacles[0] == scene.Obstacle()
    assert scenario.cars[2].attack.of("bias") == attacks.Bias()
    for where, bad in (("planner", {"no_such_key": 1}), ("world", {"obstacles": [{"corners": []}]})):
        with pytest.raises(ConfigError, match="unknown key"):
            from_dict(Scenario, dict(data, **{where: bad}), "")


def test_a_unit_comes_from_the_name_or_the_docstring():
    assert reference.unit_of("max_turn_accel_radps2", "") == "rad/s^2"
    assert reference.unit_of("command_rate_hz", "") == "Hz"
    assert reference.unit_of("qc", "Power spectral density of the prior, in m^2/s^3.") == "m^2/s^3"
    assert reference.unit_of("support_states", "N, the number of support states x_i of a plan.") == ""
    keys = {(s.path, k.name): k for s in reference.sections() for k in s.keys}
    assert keys[("tracking", "k_heading")].unit == "1/m"
    assert keys[("cars", "route")].unit == "m" and keys[("cars", "start")].unit == "m"
    assert keys[("trust", "forgetting")].unit == ""


def test_types_read_as_toml_names_them():
    keys = {(s.path, k.name): k.type for s in reference.sections() for k in s.keys}
    assert keys[("", "cars")] == "array of tables" and keys[("", "planner")] == "table"
    assert keys[("cars", "start_heading_rad")] == "float"  # optional: left out, not null
    assert keys[("cars", "route")] == "array of arrays of 2 floats"
    assert keys[("world", "bounds_m")] == "array of 4 floats"
    assert keys[("bus", "listen")] == "array of strings"
    assert keys[("cars.attack", "params")] == "table of floats"
    assert keys[("planner", "support_states")] == "integer" and keys[("guard", "enabled")] == "boolean"


def test_the_meaning_is_plain_text_of_the_first_paragraph():
    assert reference.plain_text(":class:`ConfigError` and ``x = 1`` and `y`\n  joined") == \
        "ConfigError and x = 1 and y joined"
    assert reference.first_paragraph("One line,\ncontinued.\n\nSecond paragraph.") == "One line, continued."


def test_a_cars_key_that_sets_a_tables_key_is_named_under_that_table():
    sections = {s.path: s for s in reference.sections()}
    assert [k.name for k in sections["bus"].per_car] == ["listen"]
    assert all(not s.per_car for path, s in sections.items() if path != "bus")
    assert "A `[[cars]]` entry may set, for its car: `listen`" in reference.render()
