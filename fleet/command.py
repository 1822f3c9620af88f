"""What every trustfg process shares: signals that stop it, and its config or a clear exit.

A command's ``main(argv)`` parses its arguments, then builds what it runs inside
:func:`configured`: a bad config file or value ends the command with one line naming the
problem and exit status 2, never a traceback.
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Callable, TypeVar

from ..agent.config import ConfigError

T = TypeVar("T")


def stop_on_signals(stop: threading.Event) -> threading.Event:
    """SIGTERM and SIGINT set ``stop`` (a process's loops end, then it cleans up)."""
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    return stop


def configured(prog: str, build: Callable[[], T]) -> T:
    """``build()``; on a :class:`ConfigError` print ``prog: error`` and exit with status 2."""
    try:
        return build()
    except ConfigError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
