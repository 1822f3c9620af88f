"""The fleet's report card, computed from executed motion.

    min distance   D[a][b] = min_t |p_a(t) - p_b(t)|, centre to centre (m)
    clearance      C[a][b] = D[a][b] - r_a - r_b; a breach is C < the required clearance
                   (SafetyConfig.clearance_m)
    obstacles      min over cars and time of d(p_a(t)) - r_a, d the signed distance field
    inconsistency  I = sum_t sigma(t) / sum_t mu(t), where mu(t) and sigma(t) are the mean
                   and the population standard deviation of the acceleration magnitudes
                   |a_a(t)| of the cars in motion at t (departed, not yet arrived), over
                   the instants with at least two cars in motion. a_a is the derivative of
                   the car's velocity vector v (cos yaw, sin yaw), a central difference
                   over ACCEL_WINDOW_S. I = 0 when every moving car accelerates alike;
                   I = 0.15 means the spread is 15 % of the typical acceleration.
"""

from __future__ import annotations

import numpy as np

from .world import SignedDistanceField

ACCEL_WINDOW_S = 0.2


def min_distance_matrix(positions: np.ndarray) -> np.ndarray:
    """positions (T, n, 2) -> D (n, n), zero diagonal."""
    diff = positions[:, :, None, :] - positions[:, None, :, :]
    distance = np.sqrt(np.sum(diff * diff, axis=-1)).min(axis=0)
    np.fill_diagonal(distance, 0.0)
    return distance


def clearance_matrix(distance: np.ndarray, radii: np.ndarray) -> np.ndarray:
    clearance = distance - radii[:, None] - radii[None, :]
    np.fill_diagonal(clearance, 0.0)
    return clearance


def breaches(clearance: np.ndarray, ids: list[int], threshold: float) -> list[list[int]]:
    """Pairs [a, b] (a before b) whose clearance fell below ``threshold``."""
    n = len(ids)
    return [[ids[a], ids[b]] for a in range(n) for b in range(a + 1, n) if clearance[a, b] < threshold]


def breach_distances(radii: np.ndarray, clearance_m: float) -> np.ndarray:
    """(n, n) centre distances below which each pair breaches (r_a + r_b + clearance)."""
    radii = np.asarray(radii, dtype=float)
    return radii[:, None] + radii[None, :] + clearance_m


def reached_at(times: np.ndarray, positions: np.ndarray, goals: np.ndarray, radius_m: float
               ) -> list[float | None]:
    """Per car, the first time it came within ``radius_m`` of its goal (None: never).
    ``positions`` (T, n, 2), ``goals`` (n, 2)."""
    near = np.linalg.norm(positions - np.asarray(goals)[None], axis=-1) <= radius_m  # (T, n)
    return [float(times[np.argmax(near[:, i])]) if near[:, i].any() else None for i in range(near.shape[1])]


def obstacle_min_clearance(positions: np.ndarray, radii: np.ndarray, sdf: SignedDistanceField) -> float:
    return float(np.min(sdf.distance(positions) - radii[None, :]))


def accelerations(times: np.ndarray, states: np.ndarray) -> np.ndarray:
    """|a| (T, n) of each car from its executed speed and heading."""
    velocity = states[:, :, 3:4] * np.stack([np.cos(states[:, :, 2]), np.sin(states[:, :, 2])], axis=-1)
    step = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    half = max(1, int(round(ACCEL_WINDOW_S / step / 2)))
    acc = np.zeros_like(velocity)
    if len(times) > 2 * half:
        acc[half:-half] = (velocity[2 * half:] - velocity[:-2 * half]) / (times[2 * half:] - times[:-2 * half])[:, None, None]
    return np.linalg.norm(acc, axis=-1)


def moving_mask(times: np.ndarray, depart_at: list[float], arrived_at: list[float | None]) -> np.ndarray:
    """(T, n): car departed and not yet arrived."""
    depart = np.array(depart_at)[None, :]
    arrive = np.array([np.inf if a is None else a for a in arrived_at])[None, :]
    return (times[:, None] >= depart) & (times[:, None] < arrive)


def inconsistency_index(times: np.ndarray, states: np.ndarray, depart_at: list[float],
                        arrived_at: list[float | None]) -> float:
    acc = accelerations(times, states)
    moving = moving_mask(times, depart_at, arrived_at)
    count = moving.sum(axis=1)
    use = count >= 2
    if not np.any(use):
        return 0.0
    masked = np.where(moving, acc, np.nan)[use]
    mean = np.nanmean(masked, axis=1)
    spread = np.nanstd(masked, axis=1)
    total = float(np.sum(mean))
    return float(np.sum(spread) / total) if total > 0 else 0.0


def _separated(trust: np.ndarray, liar: int, honest: list[int], gap: float) -> np.ndarray:
    """Per trust sample: every honest car trusts the liar at least ``gap`` less than every
    honest peer."""
    ok = np.ones(trust.shape[0], dtype=bool)
    for a in honest:
        peers = [b for b in honest if b != a]
        if not peers:
            continue
        ok &= trust[:, a, liar] <= trust[:, a, peers].min(axis=1) - gap
    return ok


def trust_separation(trust_times: np.ndarray, trust: np.ndarray, liar: int, honest: list[int],
                     gap: float) -> float | None:
    """First time from which every honest car's trust in the liar stays at least ``gap``
    below its trust in every honest peer until the end; None if it never settles."""
    ok = _separated(trust, liar, honest, gap)
    if not ok[-1]:
        return None
    bad = np.nonzero(~ok)[0]
    return float(trust_times[0] if len(bad) == 0 else trust_times[min(bad[-1] + 1, len(trust_times) - 1)])


def trust_detection(trust_times: np.ndarray, trust: np.ndarray, liar: int, honest: list[int],
                    gap: float) -> float | None:
    """First time at which every honest car's trust in the liar is at least ``gap`` below
    its trust in every honest peer (it may recover later: on-off liars); None if never."""
    ok = np.nonzero(_separated(trust, liar, honest, gap))[0]
    return float(trust_times[ok[0]]) if len(ok) else None
