"""A plan's GP interpolation at many times in one compiled loop (numba): agent.gp's formulas.

``Plan.state_at`` and ``Plan.acceleration_at`` (agent.gp) hand their work here when they
are asked for more than a few times at once -- the planner (peers at every check time),
verification, the audit -- where numpy's some thirty calls on small arrays cost more than
the arithmetic. Every operation is the numpy form's, in its order, so the numbers are the
same to the last bit (tests/agent/test_gp.py holds them to agent.gp's plain-float form).

agent.gp imports this module only when it needs it: the command loop, which asks for one
time at a time, never loads numba.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _where(t0, dt, n, time):
    """(s, i, u): time in support intervals from t0, the interval it falls in (clamped to
    the plan) and how far into it, 0..1."""
    s = (time - t0) / dt
    index = min(max(np.floor(s), 0.0), n - 2)
    return s, int(index), min(max(s - index, 0.0), 1.0)


@numba.njit(cache=True, nogil=True)
def _states(t0, dt, positions, velocities, times, pos, vel):
    n = positions.shape[0]
    for q in range(times.shape[0]):
        s, i, u = _where(t0, dt, n, times[q])
        # Cubic Hermite form of Lambda/Psi (agent.gp): h00 p0 + h10 dt v0 + h01 p1 + h11 dt v1
        # with h01 = 3u^2 - 2u^3 = 1 - h00, and its time derivative.
        u2 = u * u
        u3 = u2 * u
        h01 = 3 * u2 - 2 * u3
        a = (u3 - 2 * u2 + u) * dt
        b = (u3 - u2) * dt
        c = 6 * (u - u2) / dt
        d = 3 * u2 - 4 * u + 1
        e = 3 * u2 - 2 * u
        for axis in range(2):
            p0, p1 = positions[i, axis], positions[i + 1, axis]
            v0, v1 = velocities[i, axis], velocities[i + 1, axis]
            pos[q, axis] = p0 + h01 * (p1 - p0) + a * v0 + b * v1
            vel[q, axis] = c * (p1 - p0) + d * v0 + e * v1
        if s <= 0.0:  # before t0 the plan holds its first state
            pos[q, 0], pos[q, 1] = positions[0, 0], positions[0, 1]
            vel[q, 0], vel[q, 1] = velocities[0, 0], velocities[0, 1]
        if s >= n - 1:  # after its end it rests at its last position
            pos[q, 0], pos[q, 1] = positions[n - 1, 0], positions[n - 1, 1]
            vel[q, 0], vel[q, 1] = 0.0, 0.0


hermite_states = _states
"""The compiled loop itself, (t0, dt, positions, velocities, times, pos, vel) -> pos, vel
filled, for other compiled loops to call (agent.gaps)."""


@numba.njit(cache=True, nogil=True)
def _accelerations(t0, dt, dt2, positions, velocities, times, acc):
    n = positions.shape[0]
    for q in range(times.shape[0]):
        s, i, u = _where(t0, dt, n, times[q])
        outside = s < 0.0 or s > n - 1
        for axis in range(2):
            p0, p1 = positions[i, axis], positions[i + 1, axis]
            v0, v1 = velocities[i, axis], velocities[i + 1, axis]
            value = (12 * u - 6) * (p0 - p1) / dt2 + (6 * u - 4) * v0 / dt + (6 * u - 2) * v1 / dt
            acc[q, axis] = 0.0 if outside else value


def states(t0: float, dt: float, positions: np.ndarray, velocities: np.ndarray, times: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (T, 2) at ``times`` (T,), which must not be NaN (the
    compiled loop does not check its indices)."""
    pos, vel = np.empty((len(times), 2)), np.empty((len(times), 2))
    _states(float(t0), float(dt), np.ascontiguousarray(positions, dtype=float),
            np.ascontiguousarray(velocities, dtype=float), times, pos, vel)
    return pos, vel


def accelerations(t0: float, dt: float, positions: np.ndarray, velocities: np.ndarray, times: np.ndarray
                  ) -> np.ndarray:
    """Accelerations (T, 2) at ``times`` (T,), not NaN."""
    acc = np.empty((len(times), 2))
    dt = float(dt)
    # dt^2 as Python computes it (libm's pow), which numba's dt**2 (a product) is not always
    _accelerations(float(t0), dt, dt**2, np.ascontiguousarray(positions, dtype=float),
                   np.ascontiguousarray(velocities, dtype=float), times, acc)
    return acc


def warm() -> None:
    """Compile (or load from the cache) before the first plan needs it."""
    line, times = np.zeros((3, 2)), np.zeros(8)
    states(0.0, 1.0, line, line, times)
    accelerations(0.0, 1.0, line, line, times)
