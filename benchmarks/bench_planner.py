"""Planner speed: cold plan and warm replan of one car, one LM iteration against the native floor.

    python benchmarks/bench_planner.py [--repeats R]

The intersection's car 1 plans against cars 2-4, timed to meet it in the middle (with 15
peers, queues of 12 more behind them), N = 21 and 41 support states. "cold" and "warm" are
whole replans (agent.safe_plan: optimise, verify, retry or fall back; a warm one every
0.2 s from the previous plan), "verify" the check alone, "plan only" the optimiser alone.
"LM iteration" is one Levenberg-Marquardt ``iterate()`` from the seeded route, against the
floor: the same graph with every Python factor replaced by a native factor of the same
keys and rows (``native_floor_graph``). "x floor" is ours over the floor's; "x native copy"
ours over a native copy of our own graph, each factor held as its own linearisation at the
same point (``native_copy_graph``): the price of calling Python factors. Both ratios are
medians of turns timed in pairs. Results: docs/results/performance.md#planner.
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

from trustfg.agent.interval_factors import chunk_bounds, chunk_keys
from trustfg.agent.planner import PeerConstraint, PlanRequest, build_graph, interval_problem, plan_trajectory, seed_plan
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
    """Median (wall ms, CPU ms) of ``fn()`` over ``repeats`` calls, and its last result.
    CPU time (this process's, all threads) does not count the time the OS gave to other
    processes, so on a shared machine it is the steadier of the two."""
    wall, cpu = [], []
    for _ in range(repeats):
        started, started_cpu = time.perf_counter(), time.process_time()
        result = fn()
        wall.append((time.perf_counter() - started) * 1e3)
        cpu.append((time.process_time() - started_cpu) * 1e3)
    return (statistics.median(wall), statistics.median(cpu)), result


def native_floor_graph(request, config, sdf, t0, dt):
    """Our graph's priors and WNOA factors plus, for every CustomFactor of ours, a native
    stand-in of the same shape: a LinearContainerFactor holding a fixed JacobianFactor on
    the same keys (a chunk's p_s, v_s) with exactly as many rows, dense over its keys as
    GTSAM holds ours."""
    graph = gtsam.NonlinearFactorGraph()
    full = build_graph(request, dataclasses.replace(config, proximity=False, consistency=False), sdf, t0, dt)
    for k in range(full.size()):
        factor = full.at(k)
        if not isinstance(factor, gtsam.CustomFactor):
            graph.add(factor)
    rows = interval_problem(request, config, sdf, t0, dt).rows
    rng = np.random.default_rng(0)
    for first, end in chunk_bounds(config.support_states - 1, config.intervals_per_factor):
        keys = chunk_keys(first, end)
        # JacobianFactor has no many-key constructor in Python: stack parts of at most
        # three keys, splitting the rows among them; the combined factor is dense over
        # all keys with (end - first) * rows rows, like ours.
        groups = [keys[i:i + 3] for i in range(0, len(keys), 3)]
        parts = gtsam.GaussianFactorGraph()
        for group, m in zip(groups, np.diff(np.linspace(0, (end - first) * rows, len(groups) + 1).astype(int))):
            terms = [x for key in group for x in (key, rng.normal(size=(m, 2)))]
            parts.add(gtsam.JacobianFactor(*terms, np.zeros(m), gtsam.noiseModel.Unit.Create(m)))
        graph.add(gtsam.LinearContainerFactor(gtsam.JacobianFactor(parts)))
    return graph


def native_copy_graph(ours, values):
    """Our graph with every CustomFactor of ours replaced by its own linearisation at
    ``values``, held by a native LinearContainerFactor: the same keys, rows and numbers
    GTSAM gets from us at that point, without the calls into Python. An iteration of it
    from ``values`` does what ours does there, but for those calls; so ours over it is
    the price of Python factors, and it over the floor that of our linear system's
    structure."""
    graph = gtsam.NonlinearFactorGraph()
    for k in range(ours.size()):
        factor = ours.at(k)
        graph.add(gtsam.LinearContainerFactor(factor.linearize(values), values)
                  if isinstance(factor, gtsam.CustomFactor) else factor)
    return graph


def lm_iterations_paired(ours_graph, floor_graph, values, lambda_initial, repeats):
    """One Levenberg-Marquardt iteration (``iterate()``: linearise, damped solve, error at
    the new point) from ``values`` of our graph and of the floor's, on fresh optimizers
    (the constructors' error evaluation is not timed), timed in turns: ours, the floor's,
    ours, ... Returns the medians (wall, CPU ms) of ours and of the floor's, and the median
    of each turn's ratio (wall, CPU): on a machine whose speed drifts from one moment to
    the next, the two of a pair see the same machine, so the ratio is steadier than the
    ratio of two medians taken a tenth of a second apart."""
    def optimizers(make_graph):
        return [gtsam.LevenbergMarquardtOptimizer(make_graph(), values, lm_params(lambda_initial))
                for _ in range(repeats)]
    ours, floor = optimizers(ours_graph), optimizers(floor_graph)
    turns = [(*timed(ours.pop().iterate, 1)[0], *timed(floor.pop().iterate, 1)[0]) for _ in range(repeats)]
    ours_wall, ours_cpu, floor_wall, floor_cpu = zip(*turns)
    ratio = (statistics.median(a / b for a, b in zip(ours_wall, floor_wall)),
             statistics.median(a / b for a, b in zip(ours_cpu, floor_cpu) if b > 0))
    return ((statistics.median(ours_wall), statistics.median(ours_cpu)),
            (statistics.median(floor_wall), statistics.median(floor_cpu)), ratio)


def lm_params(lambda_initial):
    params = gtsam.LevenbergMarquardtParams()
    params.setlambdaInitial(lambda_initial)
    params.setDiagonalDamping(True)
    return params


def accepting_lambda(graph, values, config):
    """The planner's initial lambda, times 10 until LM accepts its first trial step from
    ``values`` (a step's cost does not depend on lambda; a rejected one costs a retry)."""
    lam = config.lambda_initial
    while True:
        optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, lm_params(lam))
        optimizer.iterate()
        if optimizer.lambda_() < lam:
            return lam
        lam *= 10.0


def first_step_accepted(make_graph, values, lambda_initial):
    optimizer = gtsam.LevenbergMarquardtOptimizer(make_graph(), values, lm_params(lambda_initial))
    optimizer.iterate()
    return optimizer.lambda_() < lambda_initial


def queued(plans, count):
    """``count`` peers: the crossing peers, then copies of them 2.5 s, 5 s, ... later --
    cars queued behind them on their approaches (the intersection with queues)."""
    return [dataclasses.replace(plans[i % len(plans)], t0=plans[i % len(plans)].t0 + 2.5 * (i // len(plans)))
            for i in range(count)]


def run(n_states: int, n_peers: int, repeats: int) -> dict:
    scenario = load_scenario("intersection")
    config = dataclasses.replace(scenario.planner, support_states=n_states, interp_checks=4)
    sdf = build_sdf(scenario.world)
    t_arrive = 12.0
    peers = queued(peer_plans(scenario, sdf, config, t_arrive), n_peers)
    ego, peer = scenario.cars[0], scenario.cars[1]
    request = ego_request(scenario, peers, t_arrive, scenario.safety.epsilon_0(ego.radius_m, peer.radius_m))
    safety = scenario.safety
    radii = [scenario.cars[1 + i % (len(scenario.cars) - 1)].radius_m for i in range(n_peers)]  # as queued()
    bounds = Bounds.of(safety.epsilon_obstacle(ego.radius_m), safety.obstacle_breach(ego.radius_m),
                       [safety.breach_distance(ego.radius_m, r) for r in radii], scenario.vehicle)

    def replan(req, last):
        return plan_safely(req, bounds, config, scenario.verify, sdf, last, clock=time.perf_counter)

    plan_only_ms, plain = timed(lambda: plan_trajectory(request, config, sdf), repeats)
    cold_ms, cold = timed(lambda: replan(request, None), repeats)
    outcomes = Counter([cold.outcome])
    verify_ms, _ = timed(lambda: verify(cold.plan, request.peers, bounds, sdf, scenario.verify), repeats * 5)

    # Warm replans: every 0.2 s, from the previous plan's state.
    warm_wall, warm_cpu, iterations, warm_plan_only = [], [], [], []
    plan, verified = cold.plan, cold.plan
    for step in range(1, repeats + 1):
        t = 0.2 * step
        (p,), (v,) = plan.state_at(t)
        warm_request = dataclasses.replace(request, t_now=t, position=p, velocity=v, warm_start=plan)
        (wall, _), _ = timed(lambda: plan_trajectory(warm_request, config, sdf), 1)  # noqa: B023
        warm_plan_only.append(wall)
        (wall, cpu), outcome = timed(lambda: replan(warm_request, verified), 1)  # noqa: B023
        warm_wall.append(wall)
        warm_cpu.append(cpu)
        outcomes[outcome.outcome] += 1
        iterations.append(outcome.result.iterations)
        plan = outcome.plan
        verified = plan if outcome.outcome != "fallback" else verified

    # One LM iteration of our graph and of the native floor, from the seeded route at
    # full resolution, where LM's first step is accepted in both.
    t0, dt = 0.0, t_arrive / (n_states - 1)
    start = seed_plan(request, t0, dt, n_states)
    values = gtsam.Values()
    for i in range(n_states):
        values.insert(X(i), start.positions[i])
        values.insert(V(i), start.velocities[i])
    lam = accepting_lambda(build_graph(request, config, sdf, t0, dt), values, config)
    ours_graph = lambda: build_graph(request, config, sdf, t0, dt)  # noqa: E731
    floor_graph = lambda: native_floor_graph(request, config, sdf, t0, dt)  # noqa: E731
    assert first_step_accepted(ours_graph, values, lam) and first_step_accepted(floor_graph, values, lam)
    ours, floor, ratio = lm_iterations_paired(ours_graph, floor_graph, values, lam, repeats * 4)
    native_copy = lambda: native_copy_graph(ours_graph(), values)  # noqa: E731
    assert first_step_accepted(native_copy, values, lam)
    _, _, over_native_copy = lm_iterations_paired(ours_graph, native_copy, values, lam, repeats * 4)
    return {"N": n_states, "peers": n_peers, "left_out": plain.peers_out_of_reach, "cold_ms": cold_ms,
            "cold_iterations": cold.result.iterations,
            "warm_ms": (statistics.median(warm_wall), statistics.median(warm_cpu)),
            "warm_iterations": statistics.median(iterations), "verify_ms": verify_ms,
            "plan_only_ms": (plan_only_ms[0], statistics.median(warm_plan_only)), "outcomes": dict(outcomes),
            "ours_iter_ms": ours, "floor_iter_ms": floor, "x_floor": ratio, "x_native_copy": over_native_copy}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print("planner benchmark: one car, 4 interpolated checks per interval; medians, wall / CPU ms;")
    print("cold and warm are whole replans: optimise + verify (+ retries or fallback when it fails);")
    print("verify: the check alone (wall / CPU); plan only: the optimiser alone, cold / warm (wall)")
    print(f"{'N':>3} {'peers':>5} {'(out)':>5} {'cold':>11} {'(iters)':>7} {'warm':>9} {'(iters)':>7} "
          f"{'verify':>9} {'plan only':>9} {'LM iteration':>12} {'floor':>9} {'x floor':>11} {'x native copy':>13}"
          "   outcomes")
    for n, peers in ((21, 3), (41, 3), (41, 15)):
        r = run(n, peers, args.repeats)
        pair = lambda x, f: f"{x[0]:{f}}/{x[1]:{f}}"  # noqa: E731
        ratio = r["x_floor"]
        print(f"{r['N']:>3} {r['peers']:>5} {r['left_out']:>5} {pair(r['cold_ms'], '.1f'):>11} "
              f"{r['cold_iterations']:>7} {pair(r['warm_ms'], '.1f'):>9} {r['warm_iterations']:>7.0f} "
              f"{pair(r['verify_ms'], '.2f'):>9} {pair(r['plan_only_ms'], '.1f'):>9} "
              f"{pair(r['ours_iter_ms'], '.2f'):>12} {pair(r['floor_iter_ms'], '.2f'):>9} {pair(ratio, '.2f'):>11}"
              f" {pair(r['x_native_copy'], '.2f'):>13}"
              f"   {r['outcomes']}")


if __name__ == "__main__":
    main()
