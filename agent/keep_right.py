"""Keep right: car-like cars that close on one another both turn to their right.

Two cars that cannot turn in place and meet head on are a symmetric problem: the proximity
hinge pushes each straight back along the line between them, both slow down, and they end
nose to nose with no room to turn away. A convention breaks the symmetry before that, as
road traffic does: each car sees a peer it closes on ahead of it shifted by ``offset`` to
the left of the line of sight, so the hinge pushes it to the right, and the two pass left
side to left side (a crowd of them turns into a roundabout).

With u the unit vector from us to the peer and n = (-u_y, u_x) its left normal, the peer
is placed at q' = q + offset n, where it is ahead (u . h > 0, h our direction of travel)
and we close on it ((v_q - v_p) . u < -MOVING_MPS). Since n is normal to the line of sight,
|p - q'|^2 = |p - q|^2 + offset^2: such a peer's epsilon becomes sqrt(eps^2 + offset^2), so
the hinge keeps eps from where the peer really is, to the extent that the plan stays where
the line of sight was judged (the previous plan). Verification checks the real plans.
Pure numpy, once per replan. docs/design/planner.md, "Car-like cars" (keeping right).
"""

from __future__ import annotations

import numpy as np

from .steering import MOVING_MPS  # slower than this a plan does not move


def keep_right(own_positions: np.ndarray, own_directions: np.ndarray, own_velocities: np.ndarray,
               peer_positions: np.ndarray, peer_velocities: np.ndarray, epsilons: np.ndarray,
               offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The peers' positions (I, K, M, 2) as the proximity hinge sees them, and their
    epsilons (M,).

    ``own_positions``, ``own_directions`` (unit), ``own_velocities``: where we are, which way
    we head and how fast we go at the check times (I, K, 2); ``peer_positions``,
    ``peer_velocities``: the peers' at the same times (I, K, M, 2)."""
    if offset <= 0.0 or peer_positions.shape[2] == 0:
        return peer_positions, epsilons
    line = peer_positions - own_positions[:, :, None, :]
    distance = np.linalg.norm(line, axis=-1)
    u = line / np.maximum(distance, 1e-9)[..., None]
    ahead = np.einsum("ikmc,ikc->ikm", u, own_directions) > 0.0
    closing = np.einsum("ikmc,ikmc->ikm", peer_velocities - own_velocities[:, :, None, :], u) < -MOVING_MPS
    shifted = ahead & closing & (distance > 1e-9)
    left = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    positions = peer_positions + offset * shifted[..., None] * left
    widened = np.where(shifted.any(axis=(0, 1)), np.sqrt(epsilons ** 2 + offset ** 2), epsilons)
    return positions, widened
