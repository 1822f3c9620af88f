"""Periodic loops on absolute deadlines.

``for deadline, now in ticks(period, stop): ...`` runs a body at start + k * period (not
every period after the last body ended, which drifts). If the loop falls more than
``max_lag_periods`` behind, the missed ticks are skipped rather than run in a burst.
It ends when ``stop`` is set; waiting on ``stop`` means it ends at once.
"""

from __future__ import annotations

import threading
import time
from typing import Iterator


def ticks(period_s: float, stop: threading.Event, max_lag_periods: float = 1.0) -> Iterator[tuple[float, float]]:
    """(deadline, now) of every tick, times on time.monotonic()."""
    start = time.monotonic()
    k = 0
    while not stop.is_set():
        k += 1
        deadline = start + k * period_s
        delay = deadline - time.monotonic()
        if delay > 0 and stop.wait(delay):
            return
        now = time.monotonic()
        if now - deadline > max_lag_periods * period_s:
            k = int((now - start) / period_s)  # fell behind: skip, do not burst
        yield deadline, now
