"""The car process's handle on its command loop (fleet.car.velocity_loop): spawn it, feed it
plans and permits, read what it reports, restart it if it dies, close it.

The loop is spawned, not forked (the car process runs Zenoh's and NatNet's threads). The
handle sends on the pipe only what changed, and renews the permit every tenth of its
lease (a pass of the car process's main loop every ~5 ms would be ~200 messages a second);
it reads the loop's report from shared memory, which never blocks either side.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import multiprocessing
import time

from ...agent.config import CarConfig, Scenario
from ...agent.gp import Plan
from ...agent.world import SignedDistanceField
from .velocity_loop import REPORT_FIELDS, REPORT_INDEX, REPORT_KINDS, LoopSettings, Permit, Report, serve

log = logging.getLogger("trustfg.fleet.car.velocity_loop")


class VelocityLoopHandle:
    """The car process's handle on its command loop: start, feed, read, restart, close."""

    def __init__(self, scenario: Scenario, car: CarConfig, sdf: SignedDistanceField):
        self.scenario = scenario
        self.car = car
        self.sdf = sdf
        self.lease_s = scenario.control.lease_s
        self._context = multiprocessing.get_context("spawn")
        self._process = None
        self._conn = None
        self._report = None
        self._plan: Plan | None = None
        self._permit = Permit()
        self._granted_at = -math.inf
        self.restarts = 0
        self.final: dict | None = None
        self.link: dict = {}

    def start(self) -> None:
        """Spawn the loop (it commands STOP from its first tick until a permit comes)."""
        parent, child = self._context.Pipe()
        self._report = self._context.Array("d", len(REPORT_FIELDS), lock=False)
        self._report[REPORT_INDEX["answered_at"]] = -math.inf
        settings = LoopSettings(self.scenario, self.car.id, self.sdf, logging.getLogger().getEffectiveLevel())
        self._process = self._context.Process(target=serve, args=(settings, child, self._report),
                                              name=f"trustfg-command-{self.car.id}", daemon=True)
        self._process.start()
        child.close()
        self._conn = parent
        if self._plan is not None:
            self._send(("plan", self._plan))

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    def keep_alive(self) -> bool:
        """A loop that died (it should not) is restarted; whether it had to be."""
        if self._process is None or self._process.is_alive():
            return False
        log.error("car %d: the command loop died (exit code %s): restarting it; the car had no commands",
                  self.car.id, self._process.exitcode)
        self.restarts += 1
        self._conn.close()
        self.start()
        self._granted_at = -math.inf
        return True

    def send_plan(self, plan: Plan | None) -> None:
        if plan is not self._plan:
            self._plan = plan
            self._send(("plan", plan))

    def grant(self, *, may_drive: bool, at_goal: bool, e_stop: bool, release: bool, trial: int,
              turn: tuple[float, float]) -> None:
        """A permit for the next ``lease_s``: sent when it changes, else renewed every
        tenth of the lease (every main-loop pass would be ~200 messages a second)."""
        now_mono = time.monotonic()
        permit = Permit(may_drive, at_goal, e_stop, release, trial, turn, now_mono + self.lease_s)
        changed = dataclasses.replace(self._permit, valid_until=permit.valid_until) != permit
        if changed or now_mono - self._granted_at >= 0.1 * self.lease_s:
            self._permit, self._granted_at = permit, now_mono
            self._send(("permit", permit))

    def report(self) -> Report:
        if self._report is None:
            return Report()
        return Report(**{name: REPORT_KINDS[name](value) for name, value in zip(REPORT_FIELDS, self._report[:])})

    def close(self, timeout_s: float = 3.0) -> None:
        """Tell the loop to stop (it sends STOP datagrams), collect its summary, reap it."""
        if self._process is None:
            return
        self._send(("quit",))
        try:
            if self._conn.poll(timeout_s):
                message = self._conn.recv()
                if message[0] == "final":
                    self.final, self.link = message[1], message[2]
        except (EOFError, OSError):  # it died first: no summary
            pass
        self._process.join(timeout_s)
        if self._process.is_alive():
            log.error("car %d: the command loop did not stop: terminating it", self.car.id)
            self._process.terminate()
            self._process.join(timeout_s)
        self._conn.close()
        self._process = None

    def _send(self, message: tuple) -> None:
        if self._conn is None:
            return
        try:
            self._conn.send(message)
        except (OSError, ValueError) as exc:  # the loop is gone; keep_alive restarts it
            log.debug("car %d: command loop unreachable: %s", self.car.id, exc)
