"""The rows of every interval check in one compiled loop (numba): agent.factors' formulas.

``evaluate`` computes, for the selected intervals i of a trajectory, the residual rows of
agent.factors (per check k: obstacle, one per peer, speed, lane x/y; then consistency) and
their Jacobian blocks d(row)/d(p_i, v_i, p_i+1, v_i+1). The numpy form of the same checks
(agent.factors.check_residuals) spends more on its many calls than on the arithmetic.
The numbers are the numpy form's, bit for bit: the checks' points come from numpy's
matmul, and every product and sum below is the numpy form's, in its order, computed
whether its hinge is active or not (tests/agent/test_interval_kernel.py).

Compiled on first use and cached on disk beside this file (numba's ``cache=True``);
``warm()`` compiles it ahead, so that many processes started at once (``trustfg sim``)
do not all compile it.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def _evaluate(p, v, intervals, weights, peer_positions, epsilons, sdf_values, origin_x, origin_y, cell,
              eps_obs, max_speed, lane, targets, delta, delta2, dt, support, jacobians, residual, blocks):
    """p, v (I, K, 2): the GP-interpolated checks of the selected intervals (numpy's
    matmul). Every product below is the numpy form's, in its order, active or not (a
    hinge off multiplies by 0.0): the same numbers, bit for bit, signed zeros too."""
    n_checks, n_peers, n_segments = weights.shape[0], epsilons.shape[0], lane.shape[0]
    per_check = n_peers + 2 + (2 if n_segments > 0 else 0)
    ny, nx = sdf_values.shape
    for out in range(intervals.shape[0]):
        i = intervals[out]
        for k in range(n_checks):
            px, py, vx, vy = p[out, k, 0], p[out, k, 1], v[out, k, 0], v[out, k, 1]
            row = k * per_check

            # Obstacle, eq. (6): c = max(0, eps - d(p)), dc/dp = -grad d where active
            # (d bilinear on the distance grid, agent.world).
            gx = min(max((px - origin_x) / cell, 0.0), nx - 1.000001)
            gy = min(max((py - origin_y) / cell, 0.0), ny - 1.000001)
            ix, iy = int(gx), int(gy)
            fx, fy = gx - ix, gy - iy
            d00, d01 = sdf_values[iy, ix], sdf_values[iy, ix + 1]
            d10, d11 = sdf_values[iy + 1, ix], sdf_values[iy + 1, ix + 1]
            bottom = d00 + fx * (d01 - d00)
            top = d10 + fx * (d11 - d10)
            distance = bottom + fy * (top - bottom)
            residual[out, row] = max(eps_obs - distance, 0.0)
            if jacobians:
                active = -1.0 if distance < eps_obs else 0.0
                dx = (((1 - fy) * (d01 - d00) + fy * (d11 - d10)) / cell) * active
                dy = ((top - bottom) / cell) * active
                for j in range(4):
                    blocks[out, j, row, 0] = dx * weights[k, 0, j]
                    blocks[out, j, row, 1] = dy * weights[k, 0, j]

            # Proximity, eq. (9): c = max(0, eps_b - |p - p_b|), dc/dp = -(p - p_b)/|p - p_b|.
            for m in range(n_peers):
                dx = px - peer_positions[i, k, m, 0]
                dy = py - peer_positions[i, k, m, 1]
                gap = math.hypot(dx, dy)
                residual[out, row + 1 + m] = max(epsilons[m] - gap, 0.0)
                if jacobians:
                    scale = -1.0 / (gap if gap > 1e-9 else 1.0) if gap < epsilons[m] else 0.0
                    dx, dy = dx * scale, dy * scale
                    for j in range(4):
                        blocks[out, j, row + 1 + m, 0] = dx * weights[k, 0, j]
                        blocks[out, j, row + 1 + m, 1] = dy * weights[k, 0, j]

            # Soft speed limit: c = max(0, |v| - vmax), dc/dv = v/|v| where active; the
            # only row that depends on v (its d/dp is zero).
            speed = math.hypot(vx, vy)
            residual[out, row + n_peers + 1] = max(speed - max_speed, 0.0)
            if jacobians:
                scale = 1.0 / (speed if speed > 1e-9 else 1.0) if speed > max_speed else 0.0
                dx, dy = vx * scale, vy * scale
                for j in range(4):
                    blocks[out, j, row + n_peers + 1, 0] = 0.0 * weights[k, 0, j] + dx * weights[k, 1, j]
                    blocks[out, j, row + n_peers + 1, 1] = 0.0 * weights[k, 0, j] + dy * weights[k, 1, j]

            if n_segments:
                # Lane keeping: p - q(p), q the nearest point of the route polyline;
                # d/dp = I - u u^T on a segment's interior (u its direction), I at an end.
                best = np.inf
                qx, qy, ux, uy, on = px, py, 0.0, 0.0, 0.0
                for s in range(n_segments):
                    ax, ay = lane[s, 0, 0], lane[s, 0, 1]
                    abx, aby = lane[s, 1, 0] - ax, lane[s, 1, 1] - ay
                    length2 = max(abx * abx + aby * aby, 1e-12)
                    rel_x, rel_y = px - ax, py - ay
                    t = (rel_x * abx + rel_y * aby) / length2
                    inside = 1.0 if 0.0 < t < 1.0 else 0.0
                    t = min(max(t, 0.0), 1.0)
                    offset_x, offset_y = rel_x - t * abx, rel_y - t * aby
                    if offset_x * offset_x + offset_y * offset_y < best:  # the first nearest, as argmin
                        best = offset_x * offset_x + offset_y * offset_y
                        qx, qy, on = px - offset_x, py - offset_y, inside
                        length = math.sqrt(length2)
                        ux, uy = abx / length, aby / length
                lane_row = row + n_peers + 2
                residual[out, lane_row] = px - qx
                residual[out, lane_row + 1] = py - qy
                if jacobians:
                    jxx, jxy = 1.0 - ux * ux * on, 0.0 - ux * uy * on
                    jyx, jyy = 0.0 - uy * ux * on, 1.0 - uy * uy * on
                    for j in range(4):
                        w = weights[k, 0, j]
                        blocks[out, j, lane_row, 0] = jxx * w
                        blocks[out, j, lane_row, 1] = jxy * w
                        blocks[out, j, lane_row + 1, 0] = jyx * w
                        blocks[out, j, lane_row + 1, 1] = jyy * w

        if targets.shape[0]:
            # Consistency: max(0, |a|_delta - abar_i), a = (v_i+1 - v_i)/dt,
            # |a|_delta = sqrt(|a|^2 + delta^2) - delta.
            ax = (support[i + 1, 2] - support[i, 2]) / dt
            ay = (support[i + 1, 3] - support[i, 3]) / dt
            root = math.sqrt(ax * ax + ay * ay + delta2)
            excess = root - delta - targets[i]
            last = residual.shape[1] - 1
            residual[out, last] = max(excess, 0.0)
            if jacobians:
                gain = (1.0 if excess > 0.0 else 0.0) / root / dt
                blocks[out, :, last] = 0.0
                blocks[out, 1, last, 0] = -(ax * gain)
                blocks[out, 1, last, 1] = -(ay * gain)
                blocks[out, 3, last, 0] = ax * gain
                blocks[out, 3, last, 1] = ay * gain


def evaluate(positions: np.ndarray, velocities: np.ndarray, intervals: np.ndarray, weights: np.ndarray,
             peer_positions: np.ndarray, epsilons: np.ndarray, sdf_values: np.ndarray, origin: tuple[float, float],
             cell_m: float, epsilon_obstacle: float, max_speed: float, lane: np.ndarray, targets: np.ndarray | None,
             delta: float, dt: float, rows: int, jacobians: bool) -> tuple[np.ndarray, np.ndarray | None]:
    """Residuals (I, rows) of ``intervals`` and, if asked, their Jacobian blocks (I, 4, rows, 2).

    The states must be finite: the compiled loop does not check its indices, so a NaN
    that reached the distance grid would read outside it. A ValueError says so instead.
    """
    c = np.ascontiguousarray  # one compiled signature (C order), and no copy when already so
    intervals = c(intervals, dtype=np.int64)
    support = np.concatenate([positions, velocities], axis=1)  # (N, 4): p, v per row
    if not np.isfinite(support).all():
        raise ValueError("interval checks asked at states that are not finite")
    # GP interpolation, [p(tau_k), v(tau_k)] = weights[k] @ (p_i, v_i, p_i+1, v_i+1) per
    # axis: numpy's matmul, so the checks are at the very points the numpy form used.
    states = np.concatenate([support[intervals], support[intervals + 1]], axis=1).reshape(-1, 4, 2)
    k = weights.shape[0]
    pv = weights.reshape(2 * k, 4) @ states  # (I, 2K, 2)
    p, v = c(pv[:, 0::2]), c(pv[:, 1::2])
    count = len(intervals)
    support = c(support)  # GTSAM's arrays come in column order
    residual = np.empty((count, rows))
    blocks = np.empty((count, 4, rows, 2) if jacobians else (0, 4, rows, 2))
    _evaluate(p, v, intervals, c(weights, dtype=float), c(peer_positions, dtype=float), c(epsilons, dtype=float),
              c(sdf_values, dtype=float), float(origin[0]), float(origin[1]), float(cell_m), float(epsilon_obstacle),
              float(max_speed), c(lane, dtype=float).reshape(-1, 2, 2),
              np.empty(0) if targets is None else c(targets, dtype=float), float(delta), float(delta)**2, float(dt),
              support,
              jacobians, residual, blocks)
    return residual, blocks if jacobians else None


def warm() -> None:
    """Compile (or load from the cache) before the first plan needs it."""
    one = np.zeros((2, 2))
    evaluate(one, one, np.array([0]), np.zeros((1, 2, 4)), np.zeros((1, 1, 0, 2)), np.zeros(0),
             np.zeros((2, 2)), (0.0, 0.0), 1.0, 0.1, 1.0, np.zeros((0, 2, 2)), None, 0.2, 1.0, 2, True)
