"""The speed a car can hold while it follows a plan's speed profile, in one compiled loop.

Verification (agent.verify) asks, for every plan it checks, how far a car falls behind a
plan that wants speed s_k at the check times t_k when its own speed u obeys
u <= v_max and |du/dt| <= a_max:

    u_0 = min(s_0 or the start speed, v_max)
    u_k = min(v_max, u_{k-1} + clip(s_k - u_{k-1}, -a_max dt, a_max dt))

A recurrence over hundreds of check times, several plans a replan, so no numpy form:
compiled (numba), with Python's own ``min``/``max`` (the first argument unless the
second is strictly smaller / larger), so the numbers are the Python loop's to the last
bit, NaN included (tests/agent/test_verify.py).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _follow(wanted, start, max_speed, dv, out):
    # Python's min(a, b) is b only if b < a, max(a, b) b only if b > a: the same here.
    out[0] = max_speed if max_speed < start else start
    for k in range(1, wanted.shape[0]):
        previous = out[k - 1]
        change = wanted[k] - previous
        change = -dv if -dv > change else change
        change = dv if dv < change else change
        speed = previous + change
        out[k] = speed if speed < max_speed else max_speed


def follower_speeds(wanted: np.ndarray, start: float, max_speed: float, dv: float) -> np.ndarray:
    """u_k above for the wanted speeds s_k (1-d, at least one), from speed ``start``, with
    at most ``dv`` change between samples."""
    wanted = np.ascontiguousarray(wanted, dtype=float)
    out = np.empty_like(wanted)
    _follow(wanted, float(start), float(max_speed), float(dv), out)
    return out


def warm() -> None:
    """Compile (or load from the cache) before the first verification needs it."""
    follower_speeds(np.zeros(3), 0.0, 1.0, 0.1)
