"""Error functions of our own factors, with analytic Jacobians.

Each function is pure: it maps the four states of one interval, (p_i, v_i, p_{i+1},
v_{i+1}), to residual rows and d(row)/d(state) blocks, which the planner wraps in GTSAM
CustomFactors (agent.planner); tests check every Jacobian against central differences.
Per check time tau_k = t_i + u_k*dt (u_0 = 0: the support state; the rest agent.gp's):

  obstacle     eqs. (4)-(6)  max(0, eps_obs - d(p(tau_k)))                1 row
  proximity    eqs. (7)-(9)  max(0, eps_ab - |p(tau_k) - p_b(tau_k)|)     1 row per peer b
  speed                      max(0, |v(tau_k)| - v_max)                   1 row
  lane                       p(tau_k) - q(p(tau_k)), q on the route       2 rows
  consistency  Sec. III.D    max(0, |a_i|_delta - abar_i), per interval   1 row

Inactive hinges are flat (zero residual and Jacobian). docs/design/planner.md, "The factors".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import interval_kernel
from .world import SignedDistanceField

SMOOTH_ACCEL_DELTA = 0.2
"""delta of the smooth magnitude |a|_delta, m/s^2: keeps the consistency row
differentiable at zero acceleration."""


@dataclass(frozen=True)
class IntervalProblem:
    """Everything an interval's residual depends on besides its own four states.

    Arrays are over intervals I, check times K and peers M.
    """

    dt: float
    weights: np.ndarray
    """(K, 2, 4): [p(tau_k), v(tau_k)] = weights[k] @ [p_i, v_i, p_i+1, v_i+1] per axis."""
    sdf: SignedDistanceField
    epsilon_obstacle: float
    peer_positions: np.ndarray
    """(I, K, M, 2) where each peer's plan says it is at each check time."""
    epsilons: np.ndarray
    """(M,) proximity threshold per peer, eps_ab = eps_0 * g(tau_b)."""
    max_speed: float
    consistency_targets: np.ndarray | None
    """(I,) abar_i, or None when the consistency factor is off."""
    lane: np.ndarray
    """(S, 2, 2) segments (a, b) of the route polyline; S = 0 turns lane keeping off."""

    @property
    def n_checks(self) -> int:
        return self.weights.shape[0]

    @property
    def n_peers(self) -> int:
        return self.peer_positions.shape[2]

    @property
    def rows(self) -> int:
        """Residual rows per interval: K checks of (obstacle, M peers, speed, lane x/y),
        then one consistency row."""
        consistency = 1 if self.consistency_targets is not None else 0
        lane = 2 if len(self.lane) else 0
        return self.n_checks * (self.n_peers + 2 + lane) + consistency


def check_sigmas(problem: IntervalProblem, sigma_obstacle: float, sigma_proximity: float,
                 sigma_speed: float, sigma_lane: float) -> np.ndarray:
    """Noise sigma of the rows of one check, in the order check_residuals emits."""
    lane = [sigma_lane, sigma_lane] if len(problem.lane) else []
    return np.concatenate([[sigma_obstacle], np.full(problem.n_peers, sigma_proximity),
                           [sigma_speed], lane])


def interval_sigmas(problem: IntervalProblem, sigma_obstacle: float, sigma_proximity: float,
                    sigma_speed: float, sigma_lane: float, sigma_consistency: float) -> np.ndarray:
    """Noise sigma of each row of one interval, in the order evaluate_intervals emits."""
    per_check = check_sigmas(problem, sigma_obstacle, sigma_proximity, sigma_speed, sigma_lane)
    parts = [np.tile(per_check, problem.n_checks)]
    if problem.consistency_targets is not None:
        parts.append([sigma_consistency])
    return np.concatenate(parts)


def hinge(epsilon: np.ndarray | float, distance: np.ndarray) -> np.ndarray:
    """max(0, epsilon - d), eqs. (6) and (9)."""
    return np.maximum(0.0, epsilon - distance)


def nearest_on_polyline(p: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point q of a polyline to points p (..., 2), and dq/dp (..., 2, 2).

    On a segment's interior q moves along the segment, dq/dp = u u^T (u its unit
    direction); at an end point q is fixed, dq/dp = 0.
    """
    a, ab = segments[:, 0], segments[:, 1] - segments[:, 0]  # (S, 2)
    length2 = np.maximum(np.einsum("sd,sd->s", ab, ab), 1e-12)
    rel = p[..., None, :] - a  # (..., S, 2)
    s = np.einsum("...sd,sd->...s", rel, ab) / length2
    interior = (s > 0.0) & (s < 1.0)
    np.clip(s, 0.0, 1.0, out=s)
    offset = (rel - s[..., None] * ab).reshape(-1, len(ab), 2)  # p - q per segment
    rows = np.arange(len(offset))
    best = np.argmin(np.einsum("nsd,nsd->ns", offset, offset), axis=-1)
    q = p - offset[rows, best].reshape(p.shape)
    unit = ab / np.sqrt(length2)[:, None]
    projector = unit[:, :, None] * unit[:, None, :]  # (S, 2, 2)
    on_interior = interior.reshape(-1, len(ab))[rows, best]
    dq_dp = (projector[best] * on_interior[:, None, None]).reshape(p.shape + (2,))
    return q, dq_dp


def check_residuals(p: np.ndarray, v: np.ndarray, peer_positions: np.ndarray,
                    epsilons: np.ndarray, sdf: SignedDistanceField, epsilon_obstacle: float,
                    max_speed: float, lane: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the checks at positions p (..., 2) with velocities v (..., 2).

    Returns the residuals (..., R) with R = M + 2 (+ 2 with a lane) rows [obstacle,
    peer 1..M, speed, lane x, lane y] and their derivatives d/dp and d/dv, (..., R, 2).
    The readable form of the checks: the planner's reference construction (``gtsam``
    interpolation) calls it per check, and agent.interval_kernel, which the planner
    uses, is tested against it.
    """
    m = peer_positions.shape[-2]
    lane_rows = 2 if lane is not None and len(lane) else 0
    shape = p.shape[:-1]
    residual = np.empty(shape + (m + 2 + lane_rows,))
    d_dp = np.zeros(shape + (m + 2 + lane_rows, 2))
    d_dv = np.zeros_like(d_dp)

    # Obstacle, eq. (6): c = max(0, eps - d(p)); dc/dp = -grad d where active.
    dist, grad = sdf.distance_and_gradient(p)
    np.maximum(epsilon_obstacle - dist, 0.0, out=residual[..., 0])
    np.multiply(grad, np.where(dist < epsilon_obstacle, -1.0, 0.0)[..., None], out=d_dp[..., 0, :])

    # Proximity, eq. (9): c = max(0, eps_b - |p - p_b|); dc/dp = -(p - p_b)/|p - p_b|.
    if m:
        diff = p[..., None, :] - peer_positions  # (..., M, 2)
        d = np.hypot(diff[..., 0], diff[..., 1])
        np.maximum(epsilons - d, 0.0, out=residual[..., 1:m + 1])
        scale = np.where(d < epsilons, -1.0 / np.where(d > 1e-9, d, 1.0), 0.0)
        np.multiply(diff, scale[..., None], out=d_dp[..., 1:m + 1, :])

    # Soft speed limit: c = max(0, |v| - vmax); dc/dv = v/|v| where active.
    speed = np.hypot(v[..., 0], v[..., 1])
    np.maximum(speed - max_speed, 0.0, out=residual[..., m + 1])
    scale = np.where(speed > max_speed, 1.0 / np.where(speed > 1e-9, speed, 1.0), 0.0)
    np.multiply(v, scale[..., None], out=d_dv[..., m + 1, :])

    if lane_rows:
        # Lane keeping: residual p - q(p); d/dp = I - dq/dp.
        q, dq_dp = nearest_on_polyline(p, lane)
        np.subtract(p, q, out=residual[..., m + 2:])
        np.subtract(np.eye(2), dq_dp, out=d_dp[..., m + 2:, :])
    return residual, d_dp, d_dv


def evaluate_intervals(problem: IntervalProblem, positions: np.ndarray, velocities: np.ndarray,
                       intervals: np.ndarray | None = None, jacobians: bool = True
                       ) -> tuple[np.ndarray, np.ndarray | None]:
    """Residuals (I, R) and Jacobians (I, R, 4, 2) of the given intervals.

    ``positions``/``velocities`` are the support states (N, 2); ``intervals`` selects which
    intervals i (default: all N-1). Jacobian block j of a row is d(row)/d(state j) with
    states ordered (p_i, v_i, p_{i+1}, v_{i+1}): the chain rule through the interpolation,
    d row/d state_j = d row/dp w_pos[k, j] + d row/dv w_vel[k, j]. The rows are those of
    check_residuals at each interpolated check, then the consistency row; computed in one
    compiled loop (agent.interval_kernel), whose tests hold it to check_residuals.
    """
    if intervals is None:
        intervals = np.arange(len(positions) - 1)
    residual, blocks = interval_kernel.evaluate(
        positions, velocities, intervals, problem.weights, problem.peer_positions,
        problem.epsilons, problem.sdf.values, problem.sdf.origin, problem.sdf.cell_m, problem.epsilon_obstacle,
        problem.max_speed, problem.lane, problem.consistency_targets, SMOOTH_ACCEL_DELTA, problem.dt,
        problem.rows, jacobians)
    return residual, None if blocks is None else blocks.transpose(0, 2, 1, 3)  # (I, R, 4, 2), a view


def check_fractions(n_interp: int) -> np.ndarray:
    """u_k of the check times within an interval: the support state, then n_interp more."""
    return np.arange(n_interp + 1) / (n_interp + 1)


def acceleration_magnitudes(velocities: np.ndarray, dt: float) -> np.ndarray:
    """|a_i| = |(v_{i+1} - v_i)/dt| of each interval of a plan (N-1,)."""
    return np.linalg.norm(np.diff(velocities, axis=0), axis=1) / dt
