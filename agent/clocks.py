"""Peers' clocks: how far each runs ahead of ours, estimated from its stamps.

A peer whose clock runs delta ahead of ours stamps a message sent at our time s with
s + delta, and we receive it at s + d (d > 0 the network's latency), so each message
gives one sample stamp - arrival = delta - d <= delta. The largest sample of the last
``clock_window_s`` is the estimate (as NTP keeps the sample with the least delay),
clipped to +- ``clock_tolerance_s``; received plans are moved onto our clock by it
before they are checked or planned against, so an honest car whose clock is off is
neither distrusted nor misplaced. docs/design/trust.md, "Clocks".
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

MAX_SAMPLES = 512
"""At most this many samples are kept per peer (the window's, bounded)."""


@dataclass
class ClockEstimate:
    """The clock offset of one peer (its clock minus ours), seconds."""

    window_s: float
    tolerance_s: float
    samples: deque = field(default_factory=lambda: deque(maxlen=MAX_SAMPLES))
    """(arrival, stamp - arrival), bounded."""
    _added: int = field(default=0, init=False, repr=False)
    """Samples ever added: the newest has index _added - 1, the oldest kept _added - len(samples)."""
    _peaks: deque = field(default_factory=deque, init=False, repr=False)
    """(index, sample) of the kept samples that no later sample equals or exceeds, oldest
    first, so their samples fall: the first is the largest kept (a sliding-window maximum,
    O(1) a message on average instead of a pass over the window)."""
    _offset: float | None = field(default=None, init=False, repr=False)
    """Cache of ``offset`` until the next sample (every received message reads it)."""

    def add(self, stamp: float, arrival: float) -> None:
        sample = stamp - arrival
        self.samples.append((arrival, sample))  # drops the oldest when full
        while self._peaks and self._peaks[-1][1] <= sample:
            self._peaks.pop()
        self._peaks.append((self._added, sample))
        self._added += 1
        while self.samples and self.samples[0][0] < arrival - self.window_s:
            self.samples.popleft()
        oldest = self._added - len(self.samples)
        while self._peaks and self._peaks[0][0] < oldest:
            self._peaks.popleft()
        self._offset = None

    @property
    def offset(self) -> float:
        if not self.samples:
            return 0.0
        if self._offset is None:
            best = self._peaks[0][1]  # the largest sample kept
            self._offset = min(self.tolerance_s, max(-self.tolerance_s, best))
        return self._offset

    def to_ours(self, stamp: float) -> float:
        """A time on the peer's clock, on ours."""
        return stamp - self.offset
