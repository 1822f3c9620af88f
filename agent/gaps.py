"""Sampled distances less their Lipschitz slack, in one compiled loop per peer (numba).

Verification (agent.verify) samples a plan at check times t_k and, for every peer, the
peer's plan at the same times. Distances are 1-Lipschitz in the relative position r_k =
p(t_k) - q(t_k), so between two samples the distance can be at most half the step
|r_k+1 - r_k| below the smaller sampled one; each sample is charged half the larger of
the steps to its neighbours:

    gap_k = |r_k| - 0.5 max(|r_k - r_k-1|, |r_k+1 - r_k|)      (end samples: their one step)

For the walls the slack is half the plan's own larger step (:func:`half_steps`). Every
operation is the numpy form's, in its order (|r| = sqrt(x*x + y*y), no fused
multiply-add; maximum NaN if either is), so the numbers are numpy's to the last bit
(tests/agent/test_gaps.py); compiled, because numpy's many small calls cost more.
"""

from __future__ import annotations

import numba
import numpy as np

from .gp import Plan
from .interpolate import hermite_states


@numba.njit(cache=True, nogil=True)
def _larger(a, b):
    """numpy's maximum: NaN if either is."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@numba.njit(cache=True, nogil=True)
def _half_steps(points, out):
    """out_k = half the larger of the steps from points_k to its neighbours (T >= 2)."""
    n = points.shape[0]
    steps = np.empty(n - 1)
    for k in range(n - 1):
        dx = points[k + 1, 0] - points[k, 0]
        dy = points[k + 1, 1] - points[k, 1]
        steps[k] = np.sqrt(dx * dx + dy * dy)
    for k in range(n):
        out[k] = 0.5 * _larger(steps[k - 1] if k > 0 else steps[0], steps[k] if k < n - 1 else steps[n - 2])


@numba.njit(cache=True, nogil=True)
def _peer_gaps(p, times, t0, dt, positions, velocities, out):
    n = times.shape[0]
    q = np.empty((n, 2))
    w = np.empty((n, 2))
    hermite_states(t0, dt, positions, velocities, times, q, w)
    rel = np.empty((n, 2))
    for k in range(n):
        rel[k, 0] = p[k, 0] - q[k, 0]
        rel[k, 1] = p[k, 1] - q[k, 1]
    half = np.zeros(n)
    if n >= 2:
        _half_steps(rel, half)
    for k in range(n):
        out[k] = np.sqrt(rel[k, 0] * rel[k, 0] + rel[k, 1] * rel[k, 1]) - half[k]


def half_steps(points: np.ndarray) -> np.ndarray:
    """Per sample, half the larger of the steps to its neighbours (points: (T, 2)); zeros
    for fewer than two."""
    out = np.zeros(len(points))
    if len(points) >= 2:
        _half_steps(np.ascontiguousarray(points, dtype=float), out)
    return out


def peer_gaps(p: np.ndarray, times: np.ndarray, peer: Plan) -> np.ndarray:
    """gap_k above between ``p`` (T, 2: our plan at ``times``) and ``peer``'s plan at the
    same ``times`` (T,: not NaN, as Plan.state_at asks)."""
    times = np.ascontiguousarray(times, dtype=float)
    if len(p) != len(times):  # the compiled loop reads p at every time
        raise ValueError(f"{len(p)} positions for {len(times)} times")
    if np.isnan(times).any():  # the compiled loop would read outside the peer's plan
        raise ValueError("a plan asked for its state at a time that is not a number")
    out = np.empty(len(times))
    _peer_gaps(np.ascontiguousarray(p, dtype=float), times, float(peer.t0), float(peer.dt),
               np.ascontiguousarray(peer.positions, dtype=float), np.ascontiguousarray(peer.velocities, dtype=float),
               out)
    return out


def warm() -> None:
    """Compile (or load from the cache) before the first verification needs it."""
    line = np.zeros((3, 2))
    peer_gaps(line, np.zeros(3), Plan(0.0, 1.0, line, line))
    half_steps(line)
