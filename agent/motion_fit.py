"""The least-squares quadratic through a track's recent positions, in one compiled loop.

agent.sightings fits p(t) = c0 + c1 (t - t_last) + c2 (t - t_last)^2 to the positions
of the last window (p = c0, v = c1, a = 2 c2 at the latest sample) every time a car's
motion is asked after a new observation: at the motion capture's rate for the car's own
track. The normal equations are solved in tau - mean(tau), where they are well
conditioned (the window is a fraction of a second, its powers small), and the
coefficients moved back to t_last; numpy's lstsq gives the same fit to rounding (tests).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def quadratic_fit(times: np.ndarray, xy: np.ndarray, t_last: float) -> np.ndarray:
    """Rows (position, velocity, acceleration) at ``t_last`` of the least-squares quadratic
    through ``xy`` (k, 2) at ``times`` (k,), k >= 3 distinct times."""
    k = times.shape[0]
    mean = 0.0
    for i in range(k):
        mean += times[i] - t_last
    mean /= k
    s2 = s3 = s4 = 0.0
    bx0 = bx1 = bx2 = by0 = by1 = by2 = 0.0
    for i in range(k):
        u = times[i] - t_last - mean
        u2 = u * u
        s2 += u2
        s3 += u2 * u
        s4 += u2 * u2
        x, y = xy[i, 0], xy[i, 1]
        bx0 += x
        bx1 += u * x
        bx2 += u2 * x
        by0 += y
        by1 += u * y
        by2 += u2 * y
    # [[k, 0, s2], [0, s2, s3], [s2, s3, s4]] d = b, by Cramer's rule (symmetric, sum u = 0).
    det = k * (s2 * s4 - s3 * s3) - s2 * s2 * s2
    out = np.empty((3, 2))
    for col in range(2):
        b0, b1, b2 = (bx0, bx1, bx2) if col == 0 else (by0, by1, by2)
        d0 = (b0 * (s2 * s4 - s3 * s3) + s2 * (b1 * s3 - s2 * b2)) / det
        d1 = (k * (b1 * s4 - s3 * b2) + s2 * (s3 * b0 - s2 * b1)) / det
        d2 = (k * (s2 * b2 - b1 * s3) - s2 * s2 * b0) / det
        # back from u = tau - mean to tau = 0 (t_last): u = -mean there
        out[0, col] = d0 - d1 * mean + d2 * mean * mean
        out[1, col] = d1 - 2.0 * d2 * mean
        out[2, col] = 2.0 * d2
    return out


def warm() -> None:
    """Compile (or load from the cache) before the first sighting needs it."""
    quadratic_fit(np.array([0.0, 0.1, 0.2]), np.zeros((3, 2)), 0.2)
