"""What a car sees of its peers when its sight is limited, and what it keeps from the unseen.

The motion capture sees every car; a car on a road sees only its neighbours
(SensingConfig). :func:`in_sight` is that sensor: which peers' poses reach a car's mind
and its proximity guard (within ``range_m``, and with a map, not behind a wall).
:func:`out_of_sight` is the mind's own view of it: the peers it knows of but has not seen
within SEEN_WITHIN_S. :func:`unseen_epsilon` is the least distance a car keeps from a peer
it does not see: that peer's plans are checked by witnesses at best, never by the car
itself. docs/design/trust.md, "Limited sight".
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from .config import TrustConfig
from .sightings import Track
from .witness import FRESH_MOTION_S
from .world import SignedDistanceField

SIGHT_STEP_M = 0.02
"""The line between two cars is checked for walls every this far (the guard's ray step):
finer than any wall of a map."""
SEEN_WITHIN_S = FRESH_MOTION_S
"""A peer is in sight while it was observed this recently (what the witness counts as
seen: agent.witness.FRESH_MOTION_S)."""


def in_sight(observer: tuple[float, float], others: np.ndarray, range_m: float,
             sdf: SignedDistanceField | None = None) -> np.ndarray:
    """Which of ``others`` (k, 2 centres) a car at ``observer`` sees: within ``range_m``
    (inf: all, walls or not) and, given the map's ``sdf``, with no wall on the straight
    line between the centres (the field is negative inside walls). (k,) booleans."""
    others = np.asarray(others, dtype=float).reshape(-1, 2)
    if math.isinf(range_m):
        return np.ones(len(others), dtype=bool)
    origin = np.asarray(observer, dtype=float)
    gaps = others - origin
    distances = np.hypot(gaps[:, 0], gaps[:, 1])
    seen = distances <= range_m
    if sdf is not None:
        for k in np.flatnonzero(seen):
            steps = max(int(math.ceil(distances[k] / SIGHT_STEP_M)), 1)
            line = origin + np.linspace(0.0, 1.0, steps + 1)[:, None] * gaps[k]
            seen[k] = bool(np.all(sdf.distance(line) >= 0.0))
    return seen


def visible(poses: dict[int, tuple], own_id: int, own_xy: tuple[float, float] | None, range_m: float,
            sdf: SignedDistanceField | None = None) -> dict[int, tuple]:
    """The poses (by car id, (x, y, ...)) a car sees: its own, and those of the peers
    :func:`in_sight` of ``own_xy`` (none while it does not know where it is). For a car
    process handed every pose the motion capture streams."""
    if math.isinf(range_m):
        return poses
    peers = [car_id for car_id in poses if car_id != own_id]
    if own_xy is None or not peers:
        return {car_id: pose for car_id, pose in poses.items() if car_id == own_id}
    seen = in_sight(tuple(own_xy[:2]), np.array([poses[car_id][:2] for car_id in peers]), range_m, sdf)
    return {car_id: pose for car_id, pose in poses.items()
            if car_id == own_id or seen[peers.index(car_id)]}


def sight_matrix(positions: np.ndarray, ranges: Iterable[float], sdf: SignedDistanceField | None = None) -> np.ndarray:
    """seen[j, i]: whether car j, at ``positions[j]`` with ``ranges[j]``, sees car i (every
    car sees itself). For a fleet stepped in one process."""
    positions = np.asarray(positions, dtype=float)
    seen = np.vstack([in_sight(positions[j], positions, r, sdf) for j, r in enumerate(ranges)])
    np.fill_diagonal(seen, True)
    return seen


def out_of_sight(tracks: dict[int, Track], known: Iterable[int], own_id: int, now: float) -> frozenset[int]:
    """The peers among ``known`` not observed within SEEN_WITHIN_S of ``now``."""
    unseen = []
    for peer in known:
        if peer == own_id:
            continue
        track = tracks.get(peer)
        last = track.last_stamp if track is not None else None
        if last is None or now - last > SEEN_WITHIN_S:
            unseen.append(peer)
    return frozenset(unseen)


def unseen_epsilon(epsilon_0: float, config: TrustConfig) -> float:
    """The least distance kept from a peer out of sight, m: eps_0, whose peer margin covers
    a plan off by up to ``transparency_tolerance_m``, plus what else a plan may be off and
    still be believed by the witnesses that check it (up to ``plan_reject_m``). With the
    defaults 0.45 + 0.15 = 0.60 m for two 0.1 m cars: never as if fully trusted."""
    return epsilon_0 + max(0.0, config.plan_reject_m - config.transparency_tolerance_m)
