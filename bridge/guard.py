"""The proximity guard: a speed cap from the poses the car sees, under any plan.

The planner keeps cars apart with soft factors against the plans peers share; when those
plans are late or missing (heavy loss, a partition) a car plans against guesses. The
guard is the hard rule underneath: a car never drives faster than it can stop before
another car seen ahead of it. For every other car j whose centre lies within
``cone_deg`` of our heading, at distance d,

    v t_r + v^2 / (2 a) <= d - d_stop     (reaction distance + braking distance)
    =>  v_max = a (-t_r + sqrt(t_r^2 + 2 (d - d_stop) / a)),   0 once d <= d_stop

with a = ``decel_mps2``, t_r = ``reaction_s``, d_stop = ``stop_distance_m``. When we are
also ahead of j (head-on), both cars close the same gap, so each may use only half of
it: d - d_stop becomes (d - d_stop) / 2. Cars beside or behind do not limit us (they see
us ahead and brake themselves), and turning is never limited, so a car held by the guard
can still turn away.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from agent.config import GuardConfig


def speed_cap(x: float, y: float, yaw: float, others: Iterable[tuple[float, float, float]],
              config: GuardConfig) -> float:
    """The highest forward speed from which the car at (x, y, yaw) still stops short of
    every car (x, y, yaw) in ``others`` ahead of it (inf when none is ahead)."""
    cap = math.inf
    cos_cone = math.cos(math.radians(config.cone_deg))
    a, t_r = config.decel_mps2, config.reaction_s
    for ox, oy, oyaw in others:
        dx, dy = ox - x, oy - y
        d = math.hypot(dx, dy)
        if d > 0.0 and (dx * math.cos(yaw) + dy * math.sin(yaw)) / d < cos_cone:
            continue  # beside or behind
        room = d - config.stop_distance_m
        if d > 0.0 and -(dx * math.cos(oyaw) + dy * math.sin(oyaw)) / d >= cos_cone:
            room /= 2.0  # it faces us too: we share the gap
        v_max = 0.0 if room <= 0.0 else a * (-t_r + math.sqrt(t_r * t_r + 2.0 * room / a))
        cap = min(cap, v_max)
    return cap
