"""Turning room: a car-like plan keeps the room to turn away from a peer that stands ahead.

A car that cannot turn in place or reverse leaves a peer in front of it only along an
arc. From p at heading theta, a peer at q (delta = q - p, distance d, a and b its parts
along and across the heading) is nearest the full-lock turn away from it at

  room = sqrt(d^2 + 2 R |b| + R^2) - R      ahead (a > 0),
  room = d                                   beside or behind (a <= 0),

the gap from q to the circle of radius R centred R to the side away from the peer; the
two agree at a = 0, and room <= d. Head on a car needs d >= sqrt(eps^2 + 2 eps R) to keep
eps on its way round, where proximity keeps only eps. The row per peer and support state
is max(0, eps_ab - room) where the peer's plan stands (slower than ``MOVING_MPS``): a
peer that moves on makes its own room. A liveness preference, softer than the proximity
hinge (``PlannerConfig.sigma_turn_room``), so that where both cannot hold the berth wins.

Pure numpy; the factors are GTSAM CustomFactors over (p_i, theta_i), chunked like
agent.heading_factors. docs/design/planner.md, "Car-like cars" (turning room).
"""

from __future__ import annotations

import functools

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X, Y

from .interval_factors import chunk_bounds
from .steering import MOVING_MPS  # a plan slower than this does not move: a peer's plan stands


def room_rows(position: np.ndarray, heading: float, peers: np.ndarray, epsilons: np.ndarray,
              radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows max(0, eps_j - room_j) of one support state against peers (M, 2).

    Returns the residual (M,), d/dp (M, 2) and d/dtheta (M,). With n the unit normal left
    of the heading, s = sign(b) (+1 at b = 0) and S = d^2 + 2 R |b| + R^2, an active row
    is -room and

      d room / d p = -(delta + R s n) / sqrt(S),   d room / d theta = -R s a / sqrt(S)
      (a <= 0:  d room / d p = -delta / d,         d room / d theta = 0)."""
    delta = np.asarray(peers, float) - np.asarray(position, float)
    h = np.array([np.cos(heading), np.sin(heading)])
    n = np.array([-h[1], h[0]])
    a, b = delta @ h, delta @ n
    d = np.hypot(delta[:, 0], delta[:, 1])
    s = np.where(b >= 0.0, 1.0, -1.0)
    root = np.sqrt(d * d + 2.0 * radius * np.abs(b) + radius * radius)
    ahead = a > 0.0
    room = np.where(ahead, root - radius, d)
    residual = np.maximum(np.asarray(epsilons, float) - room, 0.0)
    active = (residual > 0.0)[:, None]
    safe_d = np.maximum(d, 1e-9)[:, None]
    # the row is eps - room: its derivatives are minus room's
    d_p = np.where(ahead[:, None], (delta + radius * s[:, None] * n) / root[:, None], delta / safe_d)
    d_theta = np.where(ahead, radius * s * a / root, 0.0)
    return residual, np.where(active, d_p, 0.0), np.where(active[:, 0], d_theta, 0.0)


def _chunk_error(peers: np.ndarray, epsilons: np.ndarray, radius: float, this: gtsam.CustomFactor,
                 values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    """peers (k, M, 2): where each peer is at the chunk's k support states; ``epsilons``
    (k, M): each peer's epsilon there, 0 where it moves (the row is then 0)."""
    keys = this.keys()
    k = len(keys) // 2
    m = epsilons.shape[1]
    residual = np.zeros(k * m)
    if H is not None:
        for j in range(2 * k):
            H[j] = np.zeros((k * m, 2 if j < k else 1))
    for j in range(k):
        position = values.atVector(keys[j])
        heading = float(values.atVector(keys[k + j])[0])
        rows, d_p, d_theta = room_rows(position, heading, peers[j], epsilons[j], radius)
        residual[j * m:(j + 1) * m] = rows
        if H is not None:
            H[j][j * m:(j + 1) * m] = d_p
            H[k + j][j * m:(j + 1) * m, 0] = d_theta
    return residual


def add_turn_room_factors(graph: gtsam.NonlinearFactorGraph, peer_positions: np.ndarray, epsilons: np.ndarray,
                          dt: float, radius: float, per_factor: int, sigma: float) -> None:
    """Rows for support states 1 .. n-2 (the first is where the car is, the last its goal)
    against every peer of the graph that stands there: ``peer_positions`` (n-1, K, M, 2)
    where each peer's plan has it at the checks of intervals 0 .. n-2 (check 0: the support
    state; agent.planner.interval_problem), ``dt`` the support states' spacing. Nothing
    without peers."""
    states, checks, m = peer_positions.shape[0], peer_positions.shape[1], len(epsilons)
    if m == 0 or states < 2 or checks < 2:
        return
    # the mean speed from each support state to the interval's last check
    span = dt * (checks - 1) / checks
    speed = np.linalg.norm(peer_positions[:, -1] - peer_positions[:, 0], axis=2) / span  # (n-1, M)
    standing = np.where(speed < MOVING_MPS, np.asarray(epsilons, float)[None, :], 0.0)
    if not np.any(standing[1:] > 0.0):
        return
    for first, end in chunk_bounds(states - 1, per_factor):
        if not np.any(standing[first + 1:end + 1] > 0.0):
            continue
        span_keys = range(first + 1, end + 1)
        keys = [X(i) for i in span_keys] + [Y(i) for i in span_keys]
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(len(span_keys) * m, sigma), keys,
                                     functools.partial(_chunk_error, np.array(peer_positions[first + 1:end + 1, 0]),
                                                       standing[first + 1:end + 1], radius)))
