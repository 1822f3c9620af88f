"""What every trustfg process shares: its parser, signals that stop it, and its config or
a clear exit.

A command's ``main(argv)`` parses its arguments with :func:`command_parser` (whose help
shows every option's default), then builds what it runs inside :func:`configured`: a bad
config file or value ends the command with one line naming the problem and exit status 2,
never a traceback.
"""

from __future__ import annotations

import argparse
import re
import signal
import sys
import threading
from typing import Callable, TypeVar

T = TypeVar("T")


_ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|obj):`~?([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")
_DEFAULT = re.compile(r"\(default(?!:) ")


def plain(text: str) -> str:
    """Help text as a terminal shows it: reStructuredText roles and literals become their
    plain words (``:class:`~a.b.C``` -> C, two backquotes -> none)."""
    text = _ROLE.sub(lambda m: m.group(1).rsplit(".", 1)[-1] if m.group(0).count("~") else m.group(1), text)
    return _LITERAL.sub(r"\1", text)


def _shown(default) -> str:
    """A default as a user would type it: a list is its items separated by spaces."""
    if isinstance(default, (list, tuple)):
        return " ".join(str(item) for item in default)
    return str(default).replace("%", "%%")


class _HelpWithDefaults(argparse.RawDescriptionHelpFormatter):
    """Keeps the description's lines, in plain text; every option with a default ends its
    help with ``(default: X)``, written one way in every command."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = _DEFAULT.sub("(default: ", plain(action.help or ""))
        default = action.default
        if ("(default" in text or action.required or default is None or default is False
                or default == argparse.SUPPRESS or default == [] or isinstance(action, argparse._HelpAction)):
            return text
        return f"{text} (default: {_shown(default)})"


class _OneLineErrors(argparse.ArgumentParser):
    """A usage error is one line on stderr and exit status 2. An option is named whole:
    with argparse's abbreviations ``trustfg faults --seed 40`` (there is no ``--seed``)
    would be taken for ``--seeds 40`` and run another matrix without a word. (Subcommands'
    parsers are of this class too, so they refuse abbreviations as well.)"""

    def __init__(self, *args, allow_abbrev: bool = False, **kwargs):
        super().__init__(*args, allow_abbrev=allow_abbrev, **kwargs)

    def error(self, message: str):
        self.exit(2, f"{self.prog}: {message} (see --help)\n")


def command_parser(prog: str, doc: str | None, whole: bool = False, **kwargs) -> argparse.ArgumentParser:
    """An argument parser for ``trustfg COMMAND``: the description is the first paragraph
    of the command module's docstring (``whole``: all of it), never cut mid-sentence; the
    help shows every default; a usage error is one line; an option is named whole."""
    description = (doc or "").strip() if whole else (doc or "").strip().split("\n\n")[0]
    if "epilog" in kwargs and kwargs["epilog"]:
        kwargs["epilog"] = plain(kwargs["epilog"])
    return _OneLineErrors(prog=prog, description=plain(description), formatter_class=_HelpWithDefaults, **kwargs)


def stop_on_signals(stop: threading.Event) -> threading.Event:
    """SIGTERM and SIGINT set ``stop`` (a process's loops end, then it cleans up)."""
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    return stop


def configured(prog: str, build: Callable[[], T]) -> T:
    """``build()``; on a :class:`ConfigError` print ``prog: error`` and exit with status 2."""
    from ..agent.config import ConfigError  # here: trustfg stop parses its arguments before the config loads

    try:
        return build()
    except ConfigError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
