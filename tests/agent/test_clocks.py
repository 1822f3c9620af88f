"""The clock estimate's sliding maximum against its definition: the largest stamp -
arrival of the samples kept (the window's last clock_window_s, at most MAX_SAMPLES)."""

import random

import pytest

from trustfg.agent.clocks import MAX_SAMPLES, ClockEstimate


def keep(kept, arrival, sample, window_s):
    """The samples kept after one more: the last MAX_SAMPLES, less those at the front that
    had fallen out of the window when it arrived."""
    kept = [*kept, (arrival, sample)][-MAX_SAMPLES:]
    while kept and kept[0][0] < arrival - window_s:
        kept.pop(0)
    return kept


@pytest.mark.parametrize("seed", range(20))
def test_offset_is_the_largest_sample_kept(seed):
    rng = random.Random(seed)
    window_s, tolerance_s = rng.choice([0.5, 2.0, 10.0]), 0.5
    clock = ClockEstimate(window_s, tolerance_s)
    kept, arrival = [], 0.0
    for _ in range(rng.choice([50, 700, 1500])):
        # mostly forward in time, sometimes bunched, now and then a step back
        arrival += rng.choice([0.0, 0.005, 0.02, 0.1, 0.6, -0.05])
        stamp = arrival + rng.uniform(-0.8, 0.8)
        clock.add(stamp, arrival)
        kept = keep(kept, arrival, stamp - arrival, window_s)
        assert list(clock.samples) == kept
        best = max(sample for _, sample in kept)
        assert clock.offset == min(tolerance_s, max(-tolerance_s, best))


def test_an_old_peak_leaves_with_its_sample():
    clock = ClockEstimate(window_s=1.0, tolerance_s=1.0)
    clock.add(0.3, 0.0)  # sample 0.3
    clock.add(1.1, 1.0)  # 0.1
    assert clock.offset == pytest.approx(0.3)
    clock.add(1.55, 1.5)  # 0.05; the 0.3 of t = 0 is out of the window now
    assert clock.offset == pytest.approx(0.1)
