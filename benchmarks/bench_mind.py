"""Where a car's mind spends its CPU, part by part, with 3, 7 and 15 peers (in-process).

    python benchmarks/bench_mind.py [--scenes circle-4 circle-8 circle-16] [--seeds 1]

Runs the in-process fleet (fleet.sim.in_process) on each scene and books the CPU time of
every agent call to one part of the mind: planning (the factor graph's optimisation),
verification, the rest of a replan (peers, start state, fallback and retries), evidence
(audits, safety, consistency), trust fusion, tracks (fitting observed motion), messages
(encoding and decoding) and seeing (taking observations). A part's time is its own:
a part called inside another is booked to the inner one. Printed per scene: simulated
seconds per CPU second of the whole run, then per agent and simulated second, each part's
CPU in milliseconds and its share; the rest of the run (physics, the cars' control ticks,
the network model) is "fleet".
"""

from __future__ import annotations

import argparse
import functools
import time
from collections import Counter

from trustfg.agent import car_agent, messages, safe_plan, sightings, trust, witness
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.sim import in_process

PARTS = {
    "planning": [(safe_plan, "plan_trajectory")],
    "verification": [(safe_plan, "verify"), (car_agent, "verify")],
    "replan, rest": [(car_agent.CarAgent, "replan")],
    "evidence": [(witness.Witness, "gather"), (car_agent.CarAgent, "receive")],
    "trust fusion": [(trust.TrustBook, "_fuse"), (trust.TrustBook, "epsilon"), (trust.TrustBook, "report")],
    "tracks": [(sightings.Track, "_fit"), (sightings.Track, "positions_at")],
    "messages": [(in_process.messages, "encode"), (in_process.messages, "decode")],
    "seeing": [(car_agent.CarAgent, "observe")],
}
"""Each part and the functions booked to it (an attribute of a module or a class)."""


class Books:
    """Exclusive CPU time per part: a call inside another part's call is taken out of it."""

    def __init__(self) -> None:
        self.cpu_s: Counter = Counter()
        self._stack: list[list] = []

    def wrap(self, part: str, function):
        @functools.wraps(function)
        def booked(*args, **kwargs):
            started = time.process_time()
            self._stack.append([part, 0.0])
            try:
                return function(*args, **kwargs)
            finally:
                _, inner = self._stack.pop()
                spent = time.process_time() - started
                self.cpu_s[part] += spent - inner
                if self._stack:
                    self._stack[-1][1] += spent

        return booked


def instrument(books: Books) -> list:
    """Wrap every booked function; returns what to restore."""
    undo = []
    for part, places in PARTS.items():
        for owner, name in places:
            if not hasattr(owner, name):
                raise SystemExit(f"bench_mind: {owner.__name__}.{name} is gone: update PARTS")
            original = getattr(owner, name)
            undo.append((owner, name, original))
            setattr(owner, name, books.wrap(part, original))
    return undo


def measure(name: str, seed: int, record_trust: bool) -> None:
    scenario = load_scenario(name)
    sdf = build_sdf(scenario.world)
    in_process.simulate(scenario, seed + 1000, sdf)  # compiled kernels and caches warm
    books = Books()
    undo = instrument(books)
    try:
        started = time.process_time()
        record = in_process.simulate(scenario, seed, sdf, record_trust=record_trust)
        total = time.process_time() - started
    finally:
        for owner, attr, original in undo:
            setattr(owner, attr, original)
    sim_s, cars = float(record.times[-1]), len(record.car_ids)
    per = 1e3 / (cars * sim_s)  # ms of CPU per agent and simulated second
    print(f"\n{name} seed {seed}: {cars} cars ({cars - 1} peers each), {sim_s:.1f} simulated s, "
          f"{sim_s / total:.3f} simulated s per CPU s, {total * per:.1f} ms of CPU per agent-second")
    parts = dict(books.cpu_s)
    parts["fleet"] = total - sum(parts.values())
    for part, cpu in sorted(parts.items(), key=lambda kv: -kv[1]):
        print(f"  {part:<14} {cpu * per:7.2f} ms  {cpu / total:6.1%}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["circle-4", "circle-8", "circle-16"])
    parser.add_argument("--seeds", type=int, default=1, help="seeds 0..K-1 (default: 1)")
    parser.add_argument("--trust-record", action="store_true",
                        help="also record every car's trust in every peer every 0.1 s, as the paper's "
                             "experiments do (the bank does not); it is booked to 'trust fusion'")
    args = parser.parse_args()
    for name in args.scenes:
        for seed in range(args.seeds):
            measure(name, seed, args.trust_record)


if __name__ == "__main__":
    main()
