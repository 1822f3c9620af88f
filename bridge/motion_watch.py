"""A car that does not move although it is told to: its command link is cut, it is
blocked, its motors are off.

After ``STUCK_AFTER_S`` in which the car was told to drive at ``STUCK_COMMAND_MPS`` or
more on average in each half of the window and its own pose moved slower than
``STUCK_MOTION_MPS``, the car is *stuck*; it is moving again once it moves at twice that.
The car process keeps commanding its plan (so the car goes again if it can) but tells its
peers the truth -- a plan that stands where the car stands, marked stuck. On average,
because a car that replans from rest commands speeds rising from zero at every replan; in
each half, because a car told to set off late in the window has not moved yet for its lag
and its acceleration (docs/design/links.md, "The motion watch"). Pure: the control loop
passes the time, the pose and the command.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

STUCK_AFTER_S = 0.8
STUCK_COMMAND_MPS = 0.1
STUCK_MOTION_MPS = 0.03


@dataclass
class MotionWatch:
    stuck: bool = False
    samples: deque = field(default_factory=deque)
    """(t, x, y, commanded v) of the control loop's driving ticks over the last STUCK_AFTER_S."""

    why: str = ""
    """What the window held when ``stuck`` last changed (for the log)."""

    def clear(self) -> None:
        self.stuck = False
        self.samples.clear()

    def add(self, now: float, x: float, y: float, v_commanded: float) -> bool:
        """Record one control tick; True when ``stuck`` changed."""
        self.samples.append((now, x, y, v_commanded))
        while self.samples and self.samples[0][0] < now - STUCK_AFTER_S:
            self.samples.popleft()
        t0, x0, y0, _ = self.samples[0]
        if now - t0 < 0.5 * STUCK_AFTER_S:
            return False
        speed = math.hypot(x - x0, y - y0) / (now - t0)
        half = t0 + 0.5 * (now - t0)
        if self.stuck:
            changed = speed > 2 * STUCK_MOTION_MPS
        else:  # the averages only for a car that stands (they walk the window at every tick)
            changed = (speed < STUCK_MOTION_MPS and now - t0 >= 0.9 * STUCK_AFTER_S
                       and _least_half_average(self.samples, half) > STUCK_COMMAND_MPS)
        if changed:
            commanded = _least_half_average(self.samples, half)
            self.stuck = not self.stuck
            least = min(v for *_, v in self.samples)
            self.why = (f"told {commanded:.2f} m/s on average in each half (least {least:.2f}) over {now - t0:.2f} s "
                        f"({len(self.samples)} ticks), moved at {speed:.3f} m/s")
        return changed


def _least_half_average(samples: deque, half: float) -> float:
    """The lesser of the average commands before ``half`` and from it on (the loop ticks steadily)."""
    early = [v for t, *_, v in samples if t < half]
    late = [v for t, *_, v in samples if t >= half]
    return min(sum(early) / len(early), sum(late) / len(late))
