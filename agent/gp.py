"""Continuous-time plans: the white-noise-on-acceleration (WNOA) Gaussian process.

A plan is N support states x_i = (p_i, v_i) at absolute times t_i = t0 + i*dt. Under the
WNOA prior (paper eq. (3); Barfoot, *State Estimation for Robotics*, ch. 11) each axis is
a double integrator, Phi(s) = [[1, s], [0, 1]], Q(s) = Qc [[s^3/3, s^2/2], [s^2/2, s]],
and the posterior mean between two support states at t_i < tau < t_{i+1} is

    x(tau) = Lambda(tau) x_i + Psi(tau) x_{i+1}
    Psi(tau)    = Q(tau - t_i) Phi(t_{i+1} - tau)^T Q(dt)^-1
    Lambda(tau) = Phi(tau - t_i) - Psi(tau) Phi(dt)

Qc cancels: the position row is the cubic Hermite spline through the two states.
GTSAM's WnoaInterpFactorPoint2 uses the same matrices (tests/agent/test_gp.py).
docs/design/planner.md, "Checks between support states".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def transition(s: float) -> np.ndarray:
    return np.array([[1.0, s], [0.0, 1.0]])


def process_covariance(s: float, qc: float = 1.0) -> np.ndarray:
    return qc * np.array([[s**3 / 3.0, s**2 / 2.0], [s**2 / 2.0, s]])


def interpolation_matrices(dt: float, tau: float, q_dt_inv: np.ndarray | None = None
                           ) -> tuple[np.ndarray, np.ndarray]:
    """(Lambda, Psi) for a time tau in [0, dt] after the left support state
    (``q_dt_inv``: Q(dt)^-1, when the caller has it already)."""
    if tau <= 0.0:
        return np.eye(2), np.zeros((2, 2))
    if tau >= dt:
        return np.zeros((2, 2)), np.eye(2)
    if q_dt_inv is None:
        q_dt_inv = np.linalg.inv(process_covariance(dt))
    psi = process_covariance(tau) @ transition(dt - tau).T @ q_dt_inv
    lam = transition(tau) - psi @ transition(dt)
    return lam, psi


def interpolation_weights(dt: float, fractions: np.ndarray) -> np.ndarray:
    """Weights W (k, 2, 4) so that [p(tau_k), v(tau_k)] = W[k] @ [p_i, v_i, p_i+1, v_i+1].

    ``fractions`` are tau/dt in [0, 1]. Row 0 of W gives the position, row 1 the velocity.
    """
    weights = np.empty((len(fractions), 2, 4))
    q_dt_inv = np.linalg.inv(process_covariance(dt))  # one inverse for every fraction
    for k, fraction in enumerate(fractions):
        lam, psi = interpolation_matrices(dt, float(fraction) * dt, q_dt_inv)
        weights[k, :, 0:2] = lam
        weights[k, :, 2:4] = psi
    return weights


FEW_TIMES = 3
"""state_at computes up to this many times in plain floats (Plan._state_rows)."""


@dataclass(frozen=True)
class Plan:
    """A car's trajectory: support states at t0 + i*dt, positions and velocities (N, 2)."""

    t0: float
    dt: float
    positions: np.ndarray
    velocities: np.ndarray

    @property
    def n(self) -> int:
        return len(self.positions)

    @property
    def t_end(self) -> float:
        return self.t0 + self.dt * (self.n - 1)

    def times(self) -> np.ndarray:
        return self.t0 + self.dt * np.arange(self.n)

    def state_at(self, times: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities at absolute times (GP interpolation): the cubic Hermite
        form of Lambda/Psi (identical to interpolation_matrices), see _state_rows.

        Before t0 the plan holds its first state; after its end it rests at its last
        position with zero velocity (a plan ends at its goal, standing still).
        """
        t = np.atleast_1d(np.asarray(times, dtype=float))
        few = t.tolist() if t.size <= FEW_TIMES and t.ndim == 1 else None
        if few is not None and all(map(math.isfinite, few)):
            rows = [self._state_rows(time) for time in few]
            return np.array([pos for pos, _ in rows]).reshape(-1, 2), np.array([vel for _, vel in rows]).reshape(-1, 2)
        from . import interpolate  # here: the command loop asks for few times, and never loads numba

        flat = _not_nan(t).ravel()
        pos, vel = interpolate.states(self.t0, self.dt, self.positions, self.velocities, flat)
        return pos.reshape(t.shape + (2,)), vel.reshape(t.shape + (2,))

    def _state_rows(self, t: float) -> tuple[list[float], list[float]]:
        """state_at's numbers for one time, in plain floats: the same operations in the
        same order, so the same numbers, at a fraction of the cost of numpy's calls on
        small arrays (the evidence and the guard ask for one or two times at a time, tens
        of thousands of times a run)."""
        s = (t - self.t0) / self.dt
        if s >= self.n - 1:  # after the end, as the general case decides it first
            return self.positions[-1].tolist(), [0.0, 0.0]
        if s <= 0.0:
            return self.positions[0].tolist(), self.velocities[0].tolist()
        i = int(min(max(math.floor(s), 0.0), self.n - 2))
        u = min(max(s - i, 0.0), 1.0)
        dt = self.dt
        (p0x, p0y), (p1x, p1y) = self.positions[i:i + 2].tolist()
        (v0x, v0y), (v1x, v1y) = self.velocities[i:i + 2].tolist()
        u2 = u * u
        u3 = u2 * u
        h01 = 3 * u2 - 2 * u3
        a, b = (u3 - 2 * u2 + u) * dt, (u3 - u2) * dt
        c, d, e = 6 * (u - u2) / dt, 3 * u2 - 4 * u + 1, 3 * u2 - 2 * u
        return ([p0x + h01 * (p1x - p0x) + a * v0x + b * v1x, p0y + h01 * (p1y - p0y) + a * v0y + b * v1y],
                [c * (p1x - p0x) + d * v0x + e * v1x, c * (p1y - p0y) + d * v0y + e * v1y])

    def position_at(self, times: np.ndarray | float) -> np.ndarray:
        return self.state_at(times)[0]

    def acceleration_at(self, times: np.ndarray | float) -> np.ndarray:
        """Acceleration of the posterior mean (piecewise linear in time), zero outside the
        plan:

            a(tau) = (12u - 6)(p0 - p1)/dt^2 + (6u - 4) v0/dt + (6u - 2) v1/dt
        """
        t = np.atleast_1d(np.asarray(times, dtype=float))
        few = t.tolist() if t.size <= FEW_TIMES and t.ndim == 1 else None
        if few is not None and all(map(math.isfinite, few)):
            return np.array([self._acceleration_row(time) for time in few]).reshape(-1, 2)
        from . import interpolate  # see state_at

        flat = _not_nan(t).ravel()
        return interpolate.accelerations(self.t0, self.dt, self.positions, self.velocities, flat).reshape(t.shape + (2,))

    def _acceleration_row(self, t: float) -> list[float]:
        """acceleration_at's numbers for one time, in plain floats, the same operations in
        the same order (the command loop's tracking asks for one time at every tick)."""
        s = (t - self.t0) / self.dt
        i = int(min(max(math.floor(s), 0.0), self.n - 2))
        u = min(max(s - i, 0.0), 1.0)
        if s < 0.0 or s > self.n - 1:
            return [0.0, 0.0]
        dt = self.dt
        (p0x, p0y), (p1x, p1y) = self.positions[i:i + 2].tolist()
        (v0x, v0y), (v1x, v1y) = self.velocities[i:i + 2].tolist()
        return [(12 * u - 6) * (p0x - p1x) / dt**2 + (6 * u - 4) * v0x / dt + (6 * u - 2) * v1x / dt,
                (12 * u - 6) * (p0y - p1y) / dt**2 + (6 * u - 4) * v0y / dt + (6 * u - 2) * v1y / dt]

    def resampled(self, t0: float, dt: float, n: int) -> "Plan":
        """The same trajectory on a new time grid (warm start of a replan)."""
        times = t0 + dt * np.arange(n)
        pos, vel = self.state_at(times)
        return Plan(t0=t0, dt=dt, positions=pos, velocities=vel)

    def shifted(self, offset: np.ndarray) -> "Plan":
        return Plan(self.t0, self.dt, self.positions + np.asarray(offset), self.velocities.copy())


def _not_nan(t: np.ndarray) -> np.ndarray:
    """Times to interpolate at; a NaN has no place on a plan (the compiled loop would read
    outside it), infinities do (before the start, after the end)."""
    if np.isnan(t).any():
        raise ValueError("a plan asked for its state at a time that is not a number")
    return t


def standing(position: np.ndarray, t: float) -> Plan:
    """The plan of a car that stays where it is from time t on (arrived, waiting, stuck)."""
    n = 3
    return Plan(t0=t, dt=1.0, positions=np.tile(np.asarray(position, dtype=float), (n, 1)),
                velocities=np.zeros((n, 2)))
