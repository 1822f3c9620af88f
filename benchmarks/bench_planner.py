"""Planner speed: cold plan and warm replan of one car with 3 peers, and the native floor.

    python benchmarks/bench_planner.py [--repeats R]

Scenario: the intersection; car 1 (south -> north) plans against the shared plans of
cars 2, 3 and 4, all timed to reach the middle together, so the proximity hinges are
active. "cold" solves from the seeded route; "warm" is a receding-horizon replan 0.2 s
later, warm-started from the previous plan (what a car does at 5 Hz). Both for N = 21
and N = 41 support states with 4 interpolated checks per interval. Each replan is the
whole of what a car does (agent.safe_plan): optimise, verify (agent.verify), and retry
or fall back when the plan fails; "outcomes" counts how the replans ended, "verify ms"
is the check alone, and "plan only" the optimiser without it.

The floor: the same graph with every one of our Python CustomFactors replaced by a
GTSAM-native factor on the same four keys with (at least) as many rows -- a
LinearContainerFactor holding a fixed JacobianFactor -- so linearising, evaluating and
solving cost what GTSAM alone costs. "x floor" is our time per LM iteration
(linearise + evaluate + solve) over the floor's.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time
from collections import Counter

import gtsam
import numpy as np
from gtsam.symbol_shorthand import V, X

from trustfg.agent.planner import PeerConstraint, PlanRequest, build_graph, interval_problem, plan_trajectory
from trustfg.agent.safe_plan import plan_safely
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.verify import Bounds, verify
from trustfg.agent.world import build_sdf


def peer_plans(scenario, sdf, config, t_arrive):
    """The peers' plans, each shifted in time so that it reaches the point where its path
    crosses the ego car's exactly when the ego car (planning alone) would be there."""
    ego = scenario.cars[0]
    eps_obstacle = scenario.safety.epsilon_obstacle(ego.radius_m)
    alone = plan_trajectory(PlanRequest(0.0, np.array(ego.start), np.zeros(2), np.array(ego.goal),
                                        t_arrive, eps_obstacle, lane=(ego.start,)), config, sdf).plan
    times = np.linspace(0.0, t_arrive, 1201)
    ego_path = alone.position_at(times)
    plans = []
    for car in scenario.cars[1:]:
        request = PlanRequest(0.0, np.array(car.start), np.zeros(2), np.array(car.goal), t_arrive,
                              scenario.safety.epsilon_obstacle(car.radius_m), lane=(car.start,))
        plan = plan_trajectory(request, config, sdf).plan
        path = plan.position_at(times)
        gaps = np.linalg.norm(ego_path[:, None, :] - path[None, :, :], axis=-1)
        i, j = np.unravel_index(np.argmin(gaps), gaps.shape)
        if gaps[i, j] < 0.1:  # the paths cross: meet there at the same time
            plan = dataclasses.replace(plan, t0=plan.t0 + times[i] - times[j])
        plans.append(plan)
    return plans


def ego_request(scenario, peers, t_arrive, epsilon):
    car = scenario.cars[0]
    return PlanRequest(0.0, np.array(car.start), np.zeros(2), np.array(car.goal), t_arrive,
                       scenario.safety.epsilon_obstacle(car.radius_m), peers=tuple(PeerConstraint(p, epsilon) for p in peers), lane=(car.start,))


def timed(fn, repeats):
    samples = []
    for _ in range(repeats):
        started = time.perf_counter()
        result = fn()
        samples.append((time.perf_counter() - started) * 1e3)
    return statistics.median(samples), result


def native_floor_graph(request, config, sdf, t0, dt):
    """Our graph's priors and WNOA factors plus native stand-ins of the same shape for
    every interval factor (keys x_i, v_i, x_i+1, v_i+1; same number of rows)."""
    n = config.support_states
    graph = gtsam.NonlinearFactorGraph()
    full = build_graph(request, dataclasses.replace(config, proximity=False, consistency=False), sdf, t0, dt)
    for k in range(full.size()):
        factor = full.at(k)
        if not isinstance(factor, gtsam.CustomFactor):
            graph.add(factor)
    rows = interval_problem(request, config, sdf, t0, dt).rows
    rng = np.random.default_rng(0)
    unit = gtsam.noiseModel.Unit.Create(rows)
    for i in range(n - 1):
        # JacobianFactor has no four-key constructor in Python: stack a 3-key and a 1-key
        # block of `rows` rows each into one four-key factor (2 x rows rows: a generous floor).
        parts = gtsam.GaussianFactorGraph()
        block = lambda: rng.normal(size=(rows, 2))  # noqa: E731
        parts.add(gtsam.JacobianFactor(X(i), block(), V(i), block(), X(i + 1), block(), np.zeros(rows), unit))
        parts.add(gtsam.JacobianFactor(V(i + 1), block(), np.zeros(rows), unit))
        graph.add(gtsam.LinearContainerFactor(gtsam.JacobianFactor(parts)))
    return graph


def per_iteration(graph, values, repeats):
    lin_ms, _ = timed(lambda: graph.linearize(values), repeats)
    err_ms, _ = timed(lambda: graph.error(values), repeats)
    linear = graph.linearize(values)
    solve_ms, _ = timed(lambda: linear.optimize(), repeats)
    return lin_ms, err_ms, solve_ms


def run(n_states: int, repeats: int) -> dict:
    scenario = load_scenario("intersection")
    config = dataclasses.replace(scenario.planner, support_states=n_states, interp_checks=4)
    sdf = build_sdf(scenario.world)
    t_arrive = 12.0
    peers = peer_plans(scenario, sdf, config, t_arrive)
    ego, peer = scenario.cars[0], scenario.cars[1]
    request = ego_request(scenario, peers, t_arrive, scenario.safety.epsilon_0(ego.radius_m, peer.radius_m))
    safety = scenario.safety
    bounds = Bounds.of(safety.epsilon_obstacle(ego.radius_m), safety.obstacle_breach(ego.radius_m),
                       [safety.breach_distance(ego.radius_m, c.radius_m) for c in scenario.cars[1:]], scenario.vehicle)

    def replan(req, last):
        return plan_safely(req, bounds, config, scenario.verify, sdf, last, clock=time.perf_counter)

    plan_only_ms, _ = timed(lambda: plan_trajectory(request, config, sdf), repeats)
    cold_ms, cold = timed(lambda: replan(request, None), repeats)
    outcomes = Counter([cold.outcome])
    verify_ms, _ = timed(lambda: verify(cold.plan, request.peers, bounds, sdf, scenario.verify), repeats * 5)

    # Warm replans: every 0.2 s, from the previous plan's state.
    warm_samples, iterations, warm_plan_only = [], [], []
    plan, verified = cold.plan, cold.plan
    for step in range(1, repeats + 1):
        t = 0.2 * step
        (p,), (v,) = plan.state_at(t)
        warm_request = dataclasses.replace(request, t_now=t, position=p, velocity=v, warm_start=plan)
        warm_plan_only.append(plan_trajectory(warm_request, config, sdf).time_ms)
        outcome = replan(warm_request, verified)
        outcomes[outcome.outcome] += 1
        warm_samples.append(outcome.result.time_ms)
        iterations.append(outcome.result.iterations)
        plan = outcome.plan
        verified = plan if outcome.outcome != "fallback" else verified

    # Per-iteration cost of our graph and of the native floor, at the cold solution.
    t0, dt = 0.0, (t_arrive - 0.0) / (n_states - 1)
    values = gtsam.Values()
    for i in range(n_states):
        values.insert(X(i), cold.plan.positions[i])
        values.insert(V(i), cold.plan.velocities[i])
    ours = per_iteration(build_graph(request, config, sdf, t0, dt), values, repeats * 5)
    floor = per_iteration(native_floor_graph(request, config, sdf, t0, dt), values, repeats * 5)
    return {
        "N": n_states,
        "cold_ms": cold_ms,
        "cold_plan_only_ms": plan_only_ms,
        "warm_plan_only_ms": statistics.median(warm_plan_only),
        "verify_ms": verify_ms,
        "outcomes": dict(outcomes),
        "cold_iterations": cold.result.iterations,
        "warm_ms": statistics.median(warm_samples),
        "warm_iterations": statistics.median(iterations),
        "ours_iter_ms": sum(ours),
        "floor_iter_ms": sum(floor),
        "ours_parts": ours,
        "floor_parts": floor,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print("planner benchmark: one car, 3 peers, 4 interpolated checks per interval (medians);")
    print("cold and warm are whole replans: optimise + verify (+ retries or fallback when it fails)")
    print(f"{'N':>3} {'cold ms':>8} {'(iters)':>7} {'warm ms':>8} {'(iters)':>7} {'verify ms':>9} "
          f"{'plan only cold/warm':>19} {'iter ms':>8} {'floor ms':>9} {'x floor':>8}   outcomes")
    for n in (21, 41):
        r = run(n, args.repeats)
        plan_only = f"{r['cold_plan_only_ms']:.1f}/{r['warm_plan_only_ms']:.1f}"
        print(f"{r['N']:>3} {r['cold_ms']:>8.1f} {r['cold_iterations']:>7} {r['warm_ms']:>8.1f} "
              f"{r['warm_iterations']:>7.0f} {r['verify_ms']:>9.2f} {plan_only:>19} {r['ours_iter_ms']:>8.2f} "
              f"{r['floor_iter_ms']:>9.2f} {r['ours_iter_ms'] / r['floor_iter_ms']:>8.1f}   {r['outcomes']}")


if __name__ == "__main__":
    main()
