"""Peers' clocks: how far each runs ahead of ours, estimated from its stamps.

Plans carry absolute times on the sender's clock. A peer whose clock runs delta ahead of
ours stamps a message sent at our time s with s + delta, and we receive it at s + d
(d > 0 the network's latency), so each message gives one sample

    stamp - arrival = delta - d   <=   delta.

The largest sample of the last ``clock_window_s`` is the estimate (as NTP keeps the
sample with the least delay): it is delta less the least latency seen, so a few
milliseconds low on a LAN, and delayed or bunched messages (TCP under loss) cannot pull it
down. It is clipped to +- ``clock_tolerance_s``; a stamp further ahead than that is
refused (agent.car_agent). Received plans are moved onto our clock by the estimate before
they are checked or planned against, so an honest car whose clock is off is neither
distrusted nor misplaced.

A liar controls its stamps, so it controls this estimate, but only within the tolerance and
only for all its messages at once: a constant shift is corrected like an honest offset
(its plans are then checked at the right time), a varying one makes its true plans miss.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


@dataclass
class ClockEstimate:
    """The clock offset of one peer (its clock minus ours), seconds."""

    window_s: float
    tolerance_s: float
    samples: deque = field(default_factory=lambda: deque(maxlen=512))
    """(arrival, stamp - arrival), bounded."""
    _offset: float | None = field(default=None, init=False, repr=False)
    """Cache of ``offset`` until the next sample (every received message reads it)."""

    def add(self, stamp: float, arrival: float) -> None:
        self.samples.append((arrival, stamp - arrival))
        while self.samples and self.samples[0][0] < arrival - self.window_s:
            self.samples.popleft()
        self._offset = None

    @property
    def offset(self) -> float:
        if not self.samples:
            return 0.0
        if self._offset is None:
            best = max(sample for _, sample in self.samples)
            self._offset = min(self.tolerance_s, max(-self.tolerance_s, best))
        return self._offset

    def to_ours(self, stamp: float) -> float:
        """A time on the peer's clock, on ours."""
        return stamp - self.offset
