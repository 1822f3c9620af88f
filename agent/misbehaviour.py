"""How a misbehaving car lies, for experiments (``misinformation``, ``false_testimony``).

Plan misinformation (paper Sec. IV.C, "40 % non-transparency"): each plan message is
falsified independently with probability p, drawn from the car's own seeded generator.
A falsified plan is the true plan displaced as a whole by an offset of length
U(FALSE_OFFSET_MIN_M, FALSE_OFFSET_MAX_M) in a uniformly random direction: it claims the
car is, and will be, somewhere it is not. Velocities, times and the goal are left true,
so nothing but a comparison with where the car is actually seen can tell.

False testimony: the car's trust reports swap success and failure evidence for every
peer (it praises liars and slanders honest cars).

The car itself always plans and drives on its true plan.
"""

from __future__ import annotations

import numpy as np

from .gp import Plan
from .messages import PeerTrust, TrustReport

FALSE_OFFSET_MIN_M = 0.4
FALSE_OFFSET_MAX_M = 0.8


def maybe_falsify(plan: Plan, probability: float, rng: np.random.Generator) -> tuple[Plan, bool]:
    """The plan to publish and whether it was falsified."""
    if probability <= 0.0 or rng.random() >= probability:
        return plan, False
    length = rng.uniform(FALSE_OFFSET_MIN_M, FALSE_OFFSET_MAX_M)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    return plan.shifted(length * np.array([np.cos(angle), np.sin(angle)])), True


def falsify_testimony(report: TrustReport) -> TrustReport:
    """Swap success and failure evidence about every peer."""
    peers = {
        peer: PeerTrust(alpha=pt.beta, beta=pt.alpha, tau=tuple(1.0 - x for x in pt.tau),
                        trust=1.0 - pt.trust, epsilon=pt.epsilon)
        for peer, pt in report.peers.items()
    }
    return TrustReport(report.sender, report.seq, report.stamp, peers)
