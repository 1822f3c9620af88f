"""What an agent sees of a car: a short history of observed poses and its motion.

Position, velocity and acceleration at the latest observation come from a least-squares
quadratic fit p(t) = c0 + c1 (t - t_last) + c2 (t - t_last)^2 over the last
``window_s`` seconds (agent.motion_fit), so p = c0, v = c1, a = 2 c2: noise on single
frames averages out without the lag of a low-pass filter on finite differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .config.planning import TRACK_HISTORY_S
from .gp import Plan
from .motion_fit import quadratic_fit

NEAREST_S = 0.05
"""An observation stands for a moment this close to it (Track.position_at)."""


@dataclass(frozen=True)
class Motion:
    stamp: float
    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    yaw: float


STALE_PREDICTION_S = 1.0
"""A peer predicted from its observed motion keeps its velocity this long, then stops."""
STANDING_SEEN_M = 0.02
"""A peer whose observations over ``trust.standing_seen_s`` all lie this close to its newest
stands still (motion capture's noise is a millimetre or so)."""

MAX_SAMPLES = 4096
"""At most this many observations are kept (2 s of a 2 kHz stream): frames that come far
faster than any motion capture sends cannot grow a track without bound."""


@dataclass
class Track:
    window_s: float = 0.4
    history_s: float = TRACK_HISTORY_S
    _buffer: np.ndarray = field(default_factory=lambda: np.empty((256, 4)), init=False, repr=False)
    """Rows (t, x, y, yaw); the live ones are ``_buffer[_lo:_hi]``, oldest first. Appends
    go at the end and old rows leave at the front, so reads are slices of one array: a
    car observes every body at the motion capture's rate, and audits read them as often."""
    _lo: int = field(default=0, init=False, repr=False)
    _hi: int = field(default=0, init=False, repr=False)
    _motion: Motion | None = field(default=None, init=False, repr=False)
    """Cache of motion(), until the next sample."""

    @property
    def samples(self) -> np.ndarray:
        """The observations kept, rows (t, x, y, yaw) oldest first: a view that the next
        ``add`` may change."""
        return self._buffer[self._lo:self._hi]

    def add(self, t: float, x: float, y: float, yaw: float) -> None:
        if not (math.isfinite(t) and math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return
        if self._hi > self._lo and t <= self._buffer[self._hi - 1, 0]:
            return  # out of order or duplicate
        if self._hi == len(self._buffer):
            self._make_room()
        self._buffer[self._hi] = (t, x, y, yaw)
        self._hi += 1
        times = self._buffer[:, 0]
        cutoff = t - self.history_s
        while times[self._lo] < cutoff or self._hi - self._lo > MAX_SAMPLES:
            self._lo += 1
        self._motion = None

    def _make_room(self) -> None:
        """Move the live rows to the front, in a larger buffer if they fill half of it."""
        live = self._hi - self._lo
        if 2 * live > len(self._buffer):
            grown = np.empty((2 * len(self._buffer), 4))
            grown[:live] = self._buffer[self._lo:self._hi]
            self._buffer = grown
        else:
            self._buffer[:live] = self._buffer[self._lo:self._hi].copy()
        self._lo, self._hi = 0, live

    def clear(self) -> None:
        self._lo = self._hi = 0
        self._motion = None

    @property
    def last_stamp(self) -> float | None:
        return float(self._buffer[self._hi - 1, 0]) if self._hi > self._lo else None

    def motion(self) -> Motion | None:
        """Fitted motion at the latest sample, or None with no observation yet."""
        if self._hi == self._lo:
            return None
        if self._motion is None:
            self._motion = self._fit()
        return self._motion

    def _fit(self) -> Motion:
        samples = self.samples
        t_last, x, y, yaw = (float(v) for v in samples[-1])
        recent = samples[np.searchsorted(samples[:, 0], t_last - self.window_s):]
        if len(recent) < 4:
            return Motion(t_last, np.array([x, y]), np.zeros(2), np.zeros(2), yaw)
        position, velocity, acceleration = quadratic_fit(recent[:, 0], recent[:, 1:3], t_last)
        return Motion(t_last, position, velocity, acceleration, yaw)

    def position_at(self, t: float) -> np.ndarray | None:
        """The observed position at time t (nearest sample within NEAREST_S), if any."""
        positions, seen = self.positions_at(np.array([t]))
        return positions[0] if seen[0] else None

    def positions_at(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Observed positions (k, 2) at ``times`` (nearest sample) and whether one was
        within NEAREST_S of each."""
        times = np.asarray(times, dtype=float)
        samples = self.samples
        if not len(samples):
            return np.zeros((len(times), 2)), np.zeros(len(times), dtype=bool)
        stamps = samples[:, 0]
        last = len(stamps) - 1  # np.minimum/np.maximum: np.clip's answer at a fraction of its cost
        right = np.minimum(np.searchsorted(stamps, times), last)
        left = np.maximum(right - 1, 0)
        nearest = np.where(np.abs(stamps[left] - times) <= np.abs(stamps[right] - times), left, right)
        return samples[nearest, 1:3], np.abs(stamps[nearest] - times) <= NEAREST_S


def predicted_plan(track: Track | None, now: float, stale_after_s: float) -> Plan | None:
    """A plan for a car from its observed motion alone (no usable plan of its own): its
    velocity kept for STALE_PREDICTION_S, then standing; None if it is not seen within
    ``stale_after_s``."""
    motion = track.motion() if track else None
    if motion is None or now - motion.stamp > stale_after_s:
        return None
    n, dt = 9, 0.25
    tau = np.arange(n) * dt
    moving = tau < STALE_PREDICTION_S
    positions = motion.position + np.minimum(tau, STALE_PREDICTION_S)[:, None] * motion.velocity
    velocities = np.where(moving[:, None], motion.velocity, 0.0)
    return Plan(t0=motion.stamp, dt=dt, positions=positions, velocities=velocities)


def standing_at(track: Track | None, now: float, standing_s: float, stale_after_s: float) -> np.ndarray | None:
    """Where a car stands if every observation of it over the last ``standing_s`` lies
    within STANDING_SEEN_M of the newest, the newest and every gap between them no older
    or longer than ``stale_after_s``; else None."""
    if track is None or track.last_stamp is None or now - track.last_stamp > stale_after_s:
        return None
    samples = track.samples
    since = samples[-1, 0] - standing_s
    if samples[0, 0] > since:
        return None  # not seen that long
    recent = samples[max(int(np.searchsorted(samples[:, 0], since, side="right")) - 1, 0):]
    if len(recent) > 1 and np.max(np.diff(recent[:, 0])) > stale_after_s:
        return None  # unseen for a while within it: it may have moved
    positions = recent[:, 1:3]
    if np.max(np.linalg.norm(positions - positions[-1], axis=1)) > STANDING_SEEN_M:
        return None
    return positions[-1].copy()
