"""Car-like plans in the factor graph: a heading per support state, and rows that keep a
plan drivable by a car that steers its front wheels (VehicleConfig.steering = "car").

Each support state gets a heading theta_i (a scalar, unwrapped: a turn past pi is a number,
not a jump). With c, s = cos, sin theta_i (of the mean (theta_i + theta_i+1) / 2 for the
chord d_i = p_i+1 - p_i):

  per state     sideways   -s v_x + c v_y;  backwards  max(0, -(c v_x + s v_y))
  per interval  sideways   -s d_x + c d_y;  backwards  max(0, -a_i),  a_i = c d_x + s d_y
                turning    max(0, |theta_i+1 - theta_i| - kappa a_i)
  start         theta_0 = the car's yaw (a prior)

kappa = 1 / R, R the vehicle's radius widened by ``planner.turn_radius_margin``. An arc of
radius R passes every row (its chord bisects its end headings, and understates its length
by under 2 % per interval: the careful side); standing, a plan's heading stays. Sigmas:
``sigma_sideways`` (m/s; x dt for a chord, m), ``sigma_turning`` (rad). Chunked like
agent.interval_factors. docs/design/planner.md, "Car-like cars".
"""

from __future__ import annotations

import functools

import gtsam
import numpy as np
from gtsam.symbol_shorthand import V, X, Y

from .interval_factors import chunk_bounds


def heading_rows(positions: np.ndarray, velocities: np.ndarray, headings: np.ndarray, dt: float,
                 curvature: float, last: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows of a run of k = m + 1 consecutive support states (m intervals): the two
    rows of every state but the last (of the last too when ``last``: the plan's final
    state), then the three of every interval.

    Returns the residual (R,), d/dp and d/dv (R, k, 2) and d/dtheta (R, k)."""
    p = np.asarray(positions, float)
    v = np.asarray(velocities, float)
    theta = np.asarray(headings, float)
    k = len(theta)
    states = k if last else k - 1
    rows = 2 * states + 3 * (k - 1)
    residual = np.zeros(rows)
    d_p = np.zeros((rows, k, 2))
    d_v = np.zeros((rows, k, 2))
    d_theta = np.zeros((rows, k))
    c, s = np.cos(theta), np.sin(theta)
    for i in range(states):
        u = c[i] * v[i, 0] + s[i] * v[i, 1]  # speed along the heading
        w = -s[i] * v[i, 0] + c[i] * v[i, 1]  # ... and across it
        # sideways: w; dw/dv = (-s, c), dw/dtheta = -u
        residual[2 * i] = w
        d_v[2 * i, i] = (-s[i], c[i])
        d_theta[2 * i, i] = -u
        # backwards: max(0, -u); d(-u)/dv = -(c, s), d(-u)/dtheta = -w
        if u < 0.0:
            residual[2 * i + 1] = -u
            d_v[2 * i + 1, i] = (-c[i], -s[i])
            d_theta[2 * i + 1, i] = -w
    for i in range(k - 1):
        row = 2 * states + 3 * i
        mean = 0.5 * (theta[i] + theta[i + 1])
        cm, sm = np.cos(mean), np.sin(mean)
        dx, dy = p[i + 1] - p[i]
        a = cm * dx + sm * dy  # the chord along the mean heading
        b = -sm * dx + cm * dy  # ... and across it
        # da/dp_i+1 = (cm, sm) = -da/dp_i, da/dtheta_j = b / 2; db/dp_i+1 = (-sm, cm) = -db/dp_i, db/dtheta_j = -a / 2
        residual[row] = b
        d_p[row, i + 1] = (-sm, cm)
        d_p[row, i] = (sm, -cm)
        d_theta[row, i:i + 2] = -0.5 * a
        if a < 0.0:
            residual[row + 1] = -a
            d_p[row + 1, i + 1] = (-cm, -sm)
            d_p[row + 1, i] = (cm, sm)
            d_theta[row + 1, i:i + 2] = -0.5 * b
        turn = theta[i + 1] - theta[i]
        excess = abs(turn) - curvature * a
        if excess > 0.0:
            sign = 1.0 if turn >= 0.0 else -1.0
            residual[row + 2] = excess
            d_p[row + 2, i + 1] = (-curvature * cm, -curvature * sm)
            d_p[row + 2, i] = (curvature * cm, curvature * sm)
            d_theta[row + 2, i] = -sign - 0.5 * curvature * b
            d_theta[row + 2, i + 1] = sign - 0.5 * curvature * b
    return residual, d_p, d_v, d_theta


def row_sigmas(states: int, intervals: int, dt: float, sigma_sideways: float, sigma_turning: float) -> np.ndarray:
    """Sigma of each row of :func:`heading_rows`, in its order."""
    return np.concatenate([np.full(2 * states, sigma_sideways),
                           np.tile([sigma_sideways * dt, sigma_sideways * dt, sigma_turning], intervals)])


def chunk_keys(first: int, end: int) -> list[int]:
    """Keys of a chunk of intervals [first, end): p_s, then v_s, then theta_s, s = first..end."""
    span = range(first, end + 1)
    return [X(s) for s in span] + [V(s) for s in span] + [Y(s) for s in span]


def _chunk_error(dt: float, curvature: float, last: bool, this: gtsam.CustomFactor, values: gtsam.Values,
                 H: list[np.ndarray] | None) -> np.ndarray:
    keys = this.keys()
    k = len(keys) // 3
    positions = np.array([values.atVector(key) for key in keys[:k]])
    velocities = np.array([values.atVector(key) for key in keys[k:2 * k]])
    headings = np.array([values.atVector(key)[0] for key in keys[2 * k:]])
    residual, d_p, d_v, d_theta = heading_rows(positions, velocities, headings, dt, curvature, last)
    if H is not None:
        for j in range(k):
            H[j] = d_p[:, j, :]
            H[k + j] = d_v[:, j, :]
            H[2 * k + j] = d_theta[:, j:j + 1]
    return residual


def add_heading_factors(graph: gtsam.NonlinearFactorGraph, n: int, dt: float, curvature: float, heading: float,
                        per_factor: int, sigma_sideways: float, sigma_turning: float) -> None:
    """The rows of :func:`heading_rows` over all n support states, chunked by
    ``per_factor`` intervals, and the prior theta_0 = ``heading``."""
    graph.add(gtsam.PriorFactorVector(Y(0), np.array([heading]), gtsam.noiseModel.Isotropic.Sigma(1, sigma_turning)))
    for first, end in chunk_bounds(n - 1, per_factor):
        last = end == n - 1
        sigmas = row_sigmas(end - first + (1 if last else 0), end - first, dt, sigma_sideways, sigma_turning)
        graph.add(gtsam.CustomFactor(gtsam.noiseModel.Diagonal.Sigmas(sigmas), chunk_keys(first, end),
                                     functools.partial(_chunk_error, dt, curvature, last)))


def insert_headings(values: gtsam.Values, headings: np.ndarray) -> None:
    """theta_i as Y(i), one-element vectors."""
    for i, theta in enumerate(headings):
        values.insert(Y(i), np.array([float(theta)]))
