"""Child processes of a launcher (``trustfg sim``, the fault lab, fleet.launch.testbed): each in its
own session, stopped for sure (SIGTERM, then SIGKILL after :func:`grace_s`), and mocap-sim's
READY line waited for."""

from __future__ import annotations

import contextlib
import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable

from ..cpu import CpuMeter

log = logging.getLogger(__name__)

READY_TIMEOUT_S = 30.0
GRACE_S = 5.0
GRACE_PER_CHILD_S = 0.25
"""Children stopped together share the cores while they wind down (a car process sends its
STOP datagrams, collects its velocity loop's summary and writes its ``--stats``): sixteen
car processes starved on two cores need more than 5 s, and one killed loses its stats."""


def grace_s(children: int) -> float:
    """How long ``children`` stopped together get from SIGTERM before SIGKILL."""
    return GRACE_S + GRACE_PER_CHILD_S * max(children - 1, 0)


class Processes:
    """Child processes, each in its own session; stopped for sure on exit."""

    def __init__(self, wrap: Callable[[str, list[str]], list[str]] | None = None) -> None:
        self.children: dict[str, subprocess.Popen] = {}
        self.killed: set[str] = set()
        self.wrap = wrap or (lambda name, argv: argv)
        self.cpu = CpuMeter()
        self.cpu.watch("launcher", os.getpid())

    def start(self, name: str, args: list[str], log_path: Path, stdout=None) -> subprocess.Popen:
        log_file = open(log_path, "a")
        argv = self.wrap(name, [sys.executable, "-m", "trustfg", *args])
        process = subprocess.Popen(argv, stdout=stdout or log_file, stderr=log_file, start_new_session=True, text=True)
        log_file.close()
        self.children[name] = process
        self.cpu.watch(name, process.pid, children=True)  # a car process with its command loop
        return process

    def stop(self, names: list[str] | None = None) -> None:
        names = list(self.children) if names is None else names
        for name in names:
            process = self.children[name]
            if process.poll() is None:
                try:
                    os.killpg(process.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        grace = grace_s(len(names))
        deadline = time.monotonic() + grace
        for name in names:
            process = self.children[name]
            try:
                process.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                log.warning("%s did not stop within %.1f s; killing it", name, grace)
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                process.wait(timeout=5)
            if process.stdout:
                process.stdout.close()

    def kill(self, name: str) -> None:
        """SIGKILL a child (a fault to inject): it is not counted as crashed."""
        self.killed.add(name)
        process = self.children[name]
        with contextlib.suppress(ProcessLookupError):
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(timeout=5)

    def crashed(self) -> list[str]:
        """Children that exited on their own with an error (before we stopped them)."""
        return [name for name, p in self.children.items()
                if p.poll() not in (None, 0) and not (name in self.killed and p.returncode == -signal.SIGKILL)]


def wait_ready(process: subprocess.Popen, stop: threading.Event) -> None:
    """Until mocap-sim prints READY (the lines before it -- the ports it bound -- are read
    from the pipe's file descriptor, so no line waits unseen in a reader's buffer)."""
    deadline = time.monotonic() + READY_TIMEOUT_S
    fd = process.stdout.fileno()
    seen = b""
    while not stop.is_set() and time.monotonic() < deadline:
        readable, _, _ = select.select([fd], [], [], 0.2)
        chunk = os.read(fd, 4096) if readable else b""
        seen += chunk
        if b"READY\n" in seen:
            return
        if (readable and not chunk) or (not readable and process.poll() is not None):
            raise RuntimeError(f"mocap-sim exited with {process.poll()} before it was ready")
    raise RuntimeError("mocap-sim did not become ready")
