"""How long planning holds the Python interpreter, and how late a 50 Hz loop beside it runs.

    python benchmarks/bench_gil.py [--peers 3 15] [--seconds 10] [--switch-ms 1]

Python threads share one interpreter lock: while GTSAM's C++ runs inside a call that does
not release it, no other Python thread runs. This is why a car's velocity loop is a
process of its own (fleet.car.velocity_loop), not a thread beside the planner. Here the
main thread replans at 5 Hz as a car does (warm replans of the intersection's car 1 against
3 or 15 peers, N = 41, a cold plan every 2 s) while a probe thread sleeps 0.5 ms over and
over, recording how much longer each sleep took, and a 50 Hz ticker thread
(fleet.car.ticker) records how late each tick ran.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import threading
import time

import numpy as np

from trustfg.agent.planner import plan_trajectory
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.car.ticker import ticks

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from bench_planner import ego_request, peer_plans, queued  # noqa: E402

PROBE_SLEEP_S = 0.0005


def measure(n_peers: int, seconds: float, switch_s: float) -> dict:
    scenario = load_scenario("intersection")
    config = dataclasses.replace(scenario.planner, support_states=41, interp_checks=4)
    sdf = build_sdf(scenario.world)
    peers = queued(peer_plans(scenario, sdf, config, 12.0), n_peers)
    ego, peer = scenario.cars[0], scenario.cars[1]
    request = ego_request(scenario, peers, 12.0, scenario.safety.epsilon_0(ego.radius_m, peer.radius_m))
    stop = threading.Event()
    gaps, late = [], []

    def probe() -> None:
        while not stop.is_set():
            before = time.perf_counter()
            time.sleep(PROBE_SLEEP_S)  # releases the lock; waking needs it back
            gaps.append(time.perf_counter() - before - PROBE_SLEEP_S)

    def ticker() -> None:
        for deadline, now in ticks(1.0 / 50.0, stop):
            late.append(max(0.0, now - deadline))

    sys.setswitchinterval(switch_s)
    threads = [threading.Thread(target=probe, daemon=True), threading.Thread(target=ticker, daemon=True)]
    for thread in threads:
        thread.start()
    replans = []
    plan, started = None, time.monotonic()
    next_replan = started
    while time.monotonic() - started < seconds:
        now = time.monotonic()
        if now >= next_replan:
            next_replan += 0.2
            t = (now - started) % 10.0
            cold = plan is None or int((now - started) / 2.0) != int((now - started - 0.2) / 2.0)
            if cold:
                result = plan_trajectory(request, config, sdf)
            else:
                (p,), (v,) = plan.state_at(t)
                result = plan_trajectory(dataclasses.replace(request, t_now=t, position=p, velocity=v,
                                                             warm_start=plan), config, sdf)
            plan = result.plan if not cold else dataclasses.replace(result.plan, t0=t)
            replans.append(result.time_ms)
        time.sleep(max(0.0, min(0.005, next_replan - time.monotonic())))
    stop.set()
    for thread in threads:
        thread.join()
    gap_ms = np.array(gaps) * 1e3
    late_ms = np.array(late) * 1e3
    return {"peers": n_peers, "replan_ms_p50": np.median(replans), "replan_ms_max": max(replans),
            "gil_gap_ms_p99": np.percentile(gap_ms, 99.9), "gil_gap_ms_max": gap_ms.max(),
            "late_ms_p50": np.median(late_ms), "late_ms_p99": np.percentile(late_ms, 99), "late_ms_max": late_ms.max()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--peers", type=int, nargs="+", default=[3, 15])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--switch-ms", type=float, default=1.0, help="interpreter switch interval (car process: 1)")
    args = parser.parse_args()
    print(f"replanning at 5 Hz beside a sleeping probe and a 50 Hz ticker, switch interval {args.switch_ms} ms")
    print(f"{'peers':>5} {'replan p50 ms':>13} {'max':>6} {'probe wait p99.9 ms':>19} {'max':>6} "
          f"{'tick late p50 ms':>16} {'p99':>6} {'max':>6}")
    for n in args.peers:
        r = measure(n, args.seconds, args.switch_ms / 1e3)
        print(f"{r['peers']:>5} {r['replan_ms_p50']:>13.1f} {r['replan_ms_max']:>6.1f} {r['gil_gap_ms_p99']:>19.2f} "
              f"{r['gil_gap_ms_max']:>6.2f} {r['late_ms_p50']:>16.2f} {r['late_ms_p99']:>6.2f} {r['late_ms_max']:>6.2f}")


if __name__ == "__main__":
    main()
