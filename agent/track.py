"""What an agent sees of a car: a short history of observed poses and its motion.

Position, velocity and acceleration at the latest observation come from a least-squares
quadratic fit p(t) = c0 + c1 (t - t_last) + c2 (t - t_last)^2 over the last
``window_s`` seconds, so p = c0, v = c1, a = 2 c2: noise on single frames averages out
without the lag of a low-pass filter on finite differences.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

NEAREST_S = 0.05
"""An observation stands for a moment this close to it (Track.position_at)."""


@dataclass(frozen=True)
class Motion:
    stamp: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    yaw: float


@dataclass
class Track:
    window_s: float = 0.4
    history_s: float = 2.0
    samples: deque = field(default_factory=deque)
    _motion: Motion | None = field(default=None, init=False, repr=False)
    _array: np.ndarray | None = field(default=None, init=False, repr=False)
    """Caches of motion() and of the samples as an array, until the next sample."""

    def add(self, t: float, x: float, y: float, yaw: float) -> None:
        if not (np.isfinite(t) and np.isfinite(x) and np.isfinite(y) and np.isfinite(yaw)):
            return
        if self.samples and t <= self.samples[-1][0]:
            return  # out of order or duplicate
        self.samples.append((t, x, y, yaw))
        while self.samples and self.samples[0][0] < t - self.history_s:
            self.samples.popleft()
        self._motion = self._array = None

    def clear(self) -> None:
        self.samples.clear()
        self._motion = self._array = None

    @property
    def last_stamp(self) -> float | None:
        return self.samples[-1][0] if self.samples else None

    def motion(self) -> Motion | None:
        """Fitted motion at the latest sample, or None with no observation yet."""
        if not self.samples:
            return None
        if self._motion is None:
            self._motion = self._fit()
        return self._motion

    def _fit(self) -> Motion:
        t_last, x, y, yaw = self.samples[-1]
        recent = [s for s in self.samples if s[0] >= t_last - self.window_s]
        if len(recent) < 4:
            return Motion(t_last, np.array([x, y]), np.zeros(2), np.zeros(2), yaw)
        data = np.asarray(recent)
        tau = data[:, 0] - t_last
        design = np.stack([np.ones_like(tau), tau, tau**2], axis=1)
        coef, *_ = np.linalg.lstsq(design, data[:, 1:3], rcond=None)
        return Motion(t_last, coef[0], coef[1], 2.0 * coef[2], yaw)

    def position_at(self, t: float) -> np.ndarray | None:
        """The observed position at time t (nearest sample within NEAREST_S), if any."""
        positions, seen = self.positions_at(np.array([t]))
        return positions[0] if seen[0] else None

    def positions_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Observed positions (k, 2) at ``times`` (nearest sample) and whether one was
        within NEAREST_S of each."""
        times = np.asarray(times, dtype=float)
        if not self.samples:
            return np.zeros((len(times), 2)), np.zeros(len(times), dtype=bool)
        if self._array is None:
            self._array = np.asarray(self.samples, dtype=float)
        stamps = self._array[:, 0]
        right = np.clip(np.searchsorted(stamps, times), 0, len(stamps) - 1)
        left = np.clip(right - 1, 0, len(stamps) - 1)
        nearest = np.where(np.abs(stamps[left] - times) <= np.abs(stamps[right] - times), left, right)
        return self._array[nearest, 1:3].copy(), np.abs(stamps[nearest] - times) <= NEAREST_S
