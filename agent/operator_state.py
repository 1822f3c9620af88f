"""How the operator runs a car: trials, the emergency stop and the deadman (pure logic).

The car process (fleet.car.process) owns one :class:`Operation` and hands it what the
operator says (start, stop, heartbeat), what the car reports (its e-stop latched) and the
time (seconds, the fleet clock); on every control tick it asks whether the car may drive
and which flags its next datagram carries. Modes::

    waiting / arrived --start(trial T)--> driving       (see take_start for the rules)
    driving --at its goal--> arrived
    arrived --steps aside for a car it walls in (agent.deadlock)--> driving (the same trial)
    driving --abort (trial T or any) | deadman | release--> waiting
    any --estop--> e_stopped --release--> waiting

A car never drives off by itself: docs/design/safety.md, "The car's side of the protocol".
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from .config import OperatorConfig
from .messages import StartMessage, StopMessage

LATCH_REPORT_GRACE_S = 0.5
"""After the last RELEASE datagram, answers that still report the latch may be from
before it (ignored for this long)."""


class Mode(str, enum.Enum):
    WAITING = "waiting"
    DRIVING = "driving"
    ARRIVED = "arrived"
    E_STOPPED = "e_stopped"


@dataclass(frozen=True)
class LinkFlags:
    """What the car process's next datagram carries besides its command."""

    e_stop: bool = False
    release: bool = False


class Operation:
    """One car's side of the operator's protocol: its modes (module docstring) and rules
    (docs/design/safety.md, "The car's side of the protocol")."""

    def __init__(self, car_id: int, config: OperatorConfig):
        self.car_id = car_id
        self.config = config
        self.mode = Mode.WAITING
        self.trial = 0
        """The trial this car took last (0: none yet)."""
        self.depart_at = math.inf
        self.cruise_mps = 0.0
        self.heartbeat_at = -math.inf
        """When the operator's heartbeat last arrived (fleet clock)."""
        self.reason = "waiting for the operator's start"
        """Why the mode is what it is, in words (logs, status)."""
        self._release_until = -math.inf
        self._unheard_start: StartMessage | None = None

    # --- what the operator says -----------------------------------------------------------

    def take_start(self, message: StartMessage, now: float) -> bool:
        """Whether the car takes this start (then ``depart_at``, ``cruise_mps`` and
        ``trial`` are its); ``reason`` says why not."""
        if self.car_id not in message.departures or message.trial == self.trial:
            return False  # not for us, or the trial we already took (a repeat, a cache)
        depart, cruise = message.departures[self.car_id]
        refusal = None
        if self.mode == Mode.DRIVING:
            refusal = f"start of trial {message.trial} ignored: driving trial {self.trial} (abort it first)"
        elif self.mode == Mode.E_STOPPED:
            refusal = f"start of trial {message.trial} ignored: e-stopped (release first)"
        elif not self.hears_operator(now):
            refusal = f"start of trial {message.trial} waits: no operator heartbeat for {self.config.deadman_s} s"
            self._unheard_start = message  # a cached start can arrive before the first heartbeat
        elif depart < now and not self.config.rejoin_trial:
            refusal = (f"start of trial {message.trial} ignored: its departure passed {now - depart:.1f} s ago "
                       "(a restarted car waits for the operator)")
        if refusal is not None:
            self.reason = refusal
            return False
        self.mode, self.trial = Mode.DRIVING, message.trial
        self.depart_at, self.cruise_mps = depart, cruise
        self._release_until = min(self._release_until, now)
        self.reason = f"trial {message.trial}: departs in {depart - now:.1f} s"
        return True

    def take_start_without_operator(self, now: float, cruise_mps: float) -> None:
        """``control.start_timeout_s`` ran out: drive now, trial 0."""
        if self.mode == Mode.WAITING:
            self.mode, self.depart_at, self.cruise_mps = Mode.DRIVING, now, cruise_mps
            self.reason = "no start from the operator in time: driving on its own"

    def take_stop(self, message: StopMessage, now: float) -> bool:
        """Apply an e-stop, release or abort naming this car; whether the mode changed."""
        if not message.names(self.car_id):
            return False
        before = self.mode
        if message.action == "estop":
            self.mode, self.depart_at = Mode.E_STOPPED, math.inf
            self._release_until = min(self._release_until, now)
            self.reason = "e-stopped by the operator"
        elif message.action == "release":
            # The car may be latched by an e-stop we never heard of (sent straight to it):
            # release it in any mode, and never resume a trial.
            self._release_until = now + self.config.release_s
            if self.mode in (Mode.E_STOPPED, Mode.DRIVING):
                self.mode, self.depart_at = Mode.WAITING, math.inf
                self.reason = "released by the operator: waiting for a start"
        elif message.action == "abort" and self.mode == Mode.DRIVING and message.trial in (0, self.trial):
            self.mode, self.depart_at = Mode.WAITING, math.inf
            self.reason = f"trial {self.trial} aborted by the operator"
        return self.mode != before

    def heard_operator(self, arrived_at: float) -> StartMessage | None:
        """The operator's heartbeat arrived; a start that waited for it, to try again."""
        self.heartbeat_at = max(self.heartbeat_at, arrived_at)
        waiting, self._unheard_start = self._unheard_start, None
        return waiting

    # --- what the car and the time say ----------------------------------------------------

    def hears_operator(self, now: float) -> bool:
        """False when the deadman is on and the operator's heartbeat is overdue."""
        return not self.config.deadman_s or now - self.heartbeat_at <= self.config.deadman_s

    def check_deadman(self, now: float) -> bool:
        """End a trial whose operator went silent; whether it did."""
        if self.mode == Mode.DRIVING and not self.hears_operator(now):
            self.mode, self.depart_at = Mode.WAITING, math.inf
            self.reason = f"trial {self.trial} ended: no operator heartbeat for {self.config.deadman_s} s (deadman)"
            return True
        return False

    def arrived(self) -> None:
        if self.mode == Mode.DRIVING:
            self.mode = Mode.ARRIVED
            self.reason = f"trial {self.trial} ended at the goal: waiting for the next start"

    def step_aside(self, now: float, peer: int) -> bool:
        """Arrived, the agent steps aside for ``peer``, which it walls in (agent.deadlock):
        the trial goes on, driving, until the car is back at its goal -- not without the
        operator's heartbeat (deadman on), never when e-stopped. Whether the mode changed."""
        if self.mode != Mode.ARRIVED or not self.hears_operator(now):
            return False
        self.mode = Mode.DRIVING
        self.reason = f"trial {self.trial}: stepping aside for car {peer}, which it walls in"
        return True

    def car_reports_latch(self, latched: bool, now: float) -> bool:
        """The car's answer says whether its e-stop is latched; whether the mode changed."""
        if not latched or self.mode == Mode.E_STOPPED or now < self._release_until + LATCH_REPORT_GRACE_S:
            return False
        self.mode, self.depart_at = Mode.E_STOPPED, math.inf
        self.reason = "the car reports its e-stop latched: waiting for the operator's release"
        return True

    # --- what the car process does now ----------------------------------------------------

    def may_drive(self, now: float) -> bool:
        return self.mode == Mode.DRIVING and now >= self.depart_at and self.hears_operator(now)

    def next_flags(self, now: float) -> LinkFlags:
        """Flags of the next datagram."""
        if self.mode == Mode.E_STOPPED:
            return LinkFlags(e_stop=True)
        if now < self._release_until and self.mode != Mode.DRIVING:
            return LinkFlags(release=True)
        return LinkFlags()
