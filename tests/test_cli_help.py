"""Every ``trustfg`` command: --help shows every default and a whole description; a user
error is one line on stderr with a non-zero exit, never a traceback."""

import argparse
import importlib
import subprocess
import sys

import pytest

from trustfg.cli import COMMANDS

pytestmark = pytest.mark.realtime


class Captured(Exception):
    pass


def parser_of(name, monkeypatch) -> argparse.ArgumentParser:
    """The parser a command builds (caught when it parses)."""
    seen = {}

    def capture(self, args=None, namespace=None):
        seen["parser"] = self
        raise Captured

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    with pytest.raises(Captured):
        importlib.import_module(COMMANDS[name][0]).main([])
    return seen["parser"]


@pytest.mark.parametrize("name", list(COMMANDS))
def test_help_shows_every_default_and_a_whole_description(name, monkeypatch):
    parser = parser_of(name, monkeypatch)
    formatter = parser._get_formatter()
    for action in parser._actions:
        default = action.default
        if action.required or default is None or default is False or default == argparse.SUPPRESS or default == []:
            continue
        text = formatter._expand_help(action) if action.help else ""
        assert "default" in text, f"{name} {'/'.join(action.option_strings) or action.dest}: {text!r}"
    description = (parser.description or "").rstrip()
    assert description and description[-1] in ".):", f"{name}: description cut off: {description[-40:]!r}"


@pytest.mark.parametrize("argv", [
    ["stop", "--config", "no-such-fleet"],
    ["stop", "--config", "intersection", "--cars", "9"],
    ["stop", "--config", "intersection", "--release", "--path", "link"],
    ["check", "--config", "intersection", "--wait", "0"],
    ["go", "--config", "no-such-fleet"],
    ["go", "--config", "intersection", "--lead", "0"],
    ["car", "--id", "9", "--config", "intersection"],
    ["car", "--id", "1", "--config", "intersection"],  # a scene has no car links
    ["car", "--id", "1", "--config", "deploy/lab/fleet-secure.toml"],  # its zenoh_config is not on this machine
    ["dashboard", "--config", "intersection", "--port", "1", "--host", "192.0.2.1"],
    ["dashboard", "--config", "deploy/lab/fleet-secure.toml", "--operator", "--host", "0.0.0.0"],
    ["sim", "--deadman", "-1"],
    ["secure-config", "--fleet", "x", "--cars", "1", "--certs", "nowhere", "--identity", "car2", "--out", "x"],
    ["keys", "--config", "lab/fleet", "--cars", "9"],
    ["keys", "--config", "lab/fleet", "--out", "/proc/no-such-folder"],  # as root: --owner is asked for first
])
def test_a_user_error_is_one_line_and_a_non_zero_exit(argv):
    done = subprocess.run([sys.executable, "-m", "trustfg", *argv], capture_output=True, text=True, timeout=60)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode != 0, done.stderr
    assert len(lines) == 1 and "Traceback" not in done.stderr, done.stderr
    assert lines[0].startswith(f"trustfg {argv[0]}"), lines


@pytest.mark.parametrize("name", list(COMMANDS))
def test_an_option_is_named_whole(name, monkeypatch):
    """Left to argparse, `trustfg faults --seed 40` would run 40 runs, taken for `--seeds`.
    Every command refuses a shortened option."""
    parser = parser_of(name, monkeypatch)
    assert parser.allow_abbrev is False


@pytest.mark.parametrize("argv", [["faults", "--seed", "3"], ["scenario", "generate", "--kind", "circle", "--car", "4",
                                                               "--out", "x.toml"]])
def test_a_shortened_option_is_a_usage_error_and_runs_nothing(argv, monkeypatch):
    """Parsed only (never run: a regression must not start a fault matrix), a subcommand's
    parser included."""
    real = argparse.ArgumentParser.parse_args
    parser = parser_of(argv[0], monkeypatch)
    with pytest.raises(SystemExit) as exit_:
        real(parser, argv[1:])
    assert exit_.value.code == 2


MARKUP = ("``", ":class:`", ":func:`", ":mod:`", ":meth:`", ":attr:`")


def parsers_of(name, monkeypatch) -> list[argparse.ArgumentParser]:
    """A command's parser and its subcommands' (``trustfg scenario generate``), and for
    ``experiment`` the parsers of the experiments with options of their own."""
    found = [parser_of(name, monkeypatch)]
    if name == "experiment":
        from trustfg.fleet.experiments.paper import STUDIES

        for study, (module, _) in STUDIES.items():
            seen = {}
            monkeypatch.setattr(argparse.ArgumentParser, "parse_args",
                                lambda self, *a, **k: (seen.setdefault("parser", self), (_ for _ in ()).throw(Captured))[1])
            with pytest.raises(Captured):
                importlib.import_module(f"trustfg.fleet.experiments.{module}").main([])
            found.append(seen["parser"])
    for parser in list(found):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                found += list(action.choices.values())
    return found


@pytest.mark.parametrize("name", list(COMMANDS))
def test_help_is_plain_text_with_defaults_written_one_way(name, monkeypatch):
    for parser in parsers_of(name, monkeypatch):
        text = parser.format_help()
        assert not [mark for mark in MARKUP if mark in text], f"{parser.prog}: markup in its help:\n{text}"
        assert "(default " not in text.replace("\n", " "), f"{parser.prog}: '(default X)' instead of '(default: X)'"
        assert parser.description, f"{parser.prog}: no description"


def test_every_experiment_and_every_fault_case_has_a_line_of_help(monkeypatch):
    from trustfg.fleet.experiments.paper import EXPERIMENTS, STUDIES
    from trustfg.fleet.faultlab.matrix import CASES

    experiments = parser_of("experiment", monkeypatch).format_help()
    for name in [*EXPERIMENTS, "all", *STUDIES]:
        assert f"\n  {name} " in experiments, name
    faults = parser_of("faults", monkeypatch).format_help()
    for name in CASES:
        family = name.rsplit("-", 1)[0] + "-" if name.startswith("loss-") else name
        assert f"\n    {family}" in faults, name
    assert faults.count("partition") == 1  # the cases are listed once, with what each does


def test_the_version_is_the_package_version():
    from trustfg import __version__

    done = subprocess.run([sys.executable, "-m", "trustfg", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == f"trustfg {__version__}"
