"""agent.sightings: observations kept in one array, checked against the plain definition."""

import math

import numpy as np
import pytest

from trustfg.agent.sightings import MAX_SAMPLES, NEAREST_S, Track


def reference(samples: list[tuple], times: np.ndarray, window_s: float):
    """What a track should say, written out on a list of (t, x, y, yaw)."""
    data = np.asarray(samples)
    nearest = [int(np.argmin(np.abs(data[:, 0] - t))) for t in times]
    positions = data[nearest, 1:3]
    seen = np.array([abs(data[i, 0] - t) <= NEAREST_S for i, t in zip(nearest, times)])
    recent = data[data[:, 0] >= data[-1, 0] - window_s]
    tau = recent[:, 0] - data[-1, 0]
    coef = np.polyfit(tau, recent[:, 1:3], 2) if len(recent) >= 4 else None
    return positions, seen, coef


@pytest.mark.parametrize("seed", range(8))
def test_a_track_keeps_what_the_last_history_holds_and_fits_it(seed):
    rng = np.random.default_rng(seed)
    track, kept = Track(), []
    t = 0.0
    for _ in range(1500):  # far more than the first buffer holds: it moves and grows
        t += float(rng.choice([1 / 120, 1 / 360, 0.05, 0.4]))
        sample = (t, math.cos(t) + rng.normal(0, 0.01), math.sin(t), 0.2)
        if rng.random() < 0.02:  # not finite: ignored
            track.add(t, math.nan, 0.0, 0.0)
        track.add(*sample)
        if rng.random() < 0.05:  # out of order or a duplicate: ignored
            track.add(t - float(rng.choice([0.0, 0.001])), 9.0, 9.0, 0.0)
        kept.append(sample)
        kept = [s for s in kept if s[0] >= t - track.history_s]
        assert np.array_equal(track.samples, np.asarray(kept))
    times = t - np.array([0.0, 0.013, 0.3, 1.0, 1.9, 2.5])
    positions, seen = track.positions_at(times)
    want_positions, want_seen, coef = reference(kept, times, track.window_s)
    assert np.array_equal(seen, want_seen)
    assert np.allclose(positions[seen], want_positions[want_seen])
    motion = track.motion()
    assert motion.stamp == t
    if coef is not None:  # p(tau) = c0 + c1 tau + c2 tau^2: polyfit lists c2 first
        assert np.allclose(motion.position, coef[2], atol=1e-9)
        assert np.allclose(motion.velocity, coef[1], atol=1e-6)


def test_a_flood_of_frames_is_bounded():
    track = Track()
    for k in range(3 * MAX_SAMPLES):
        track.add(k * 1e-5, 0.0, 0.0, 0.0)  # 100 kHz: within the history, beyond any mocap
    assert len(track.samples) == MAX_SAMPLES
    assert track.samples[-1, 0] == (3 * MAX_SAMPLES - 1) * 1e-5


def test_an_empty_or_cleared_track_has_no_motion():
    track = Track()
    assert track.motion() is None and track.last_stamp is None
    track.add(1.0, 2.0, 3.0, 0.5)
    assert track.motion().position.tolist() == [2.0, 3.0]
    positions, seen = track.positions_at(np.array([1.0, 1.2]))
    assert seen.tolist() == [True, False] and positions[0].tolist() == [2.0, 3.0]
    track.clear()
    assert track.motion() is None and len(track.samples) == 0
    assert not track.positions_at(np.array([1.0]))[1].any()
