"""Plan one car's trajectory with the factor graph, around a peer's plan, and verify it.

Car 2 of the intersection drives west to east, having set off ``--head-start`` seconds
earlier; car 1 drives south to north and would meet it in the middle. Car 1 plans twice:
alone (agent.planner), and with car 2's plan as a PeerConstraint at eps_0 (the proximity
hinge, eq. (9) of the paper), made safe by agent.safe_plan. agent.verify checks both
against car 2's plan and the walls. Prints iterations, errors and clearances; draws the
plans and the distance between the cars over time.

    .venv/bin/python examples/plan_one_car.py [--scenario intersection] [--out DIR]
"""

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trustfg.agent.planner import PeerConstraint, PlanRequest, plan_trajectory
from trustfg.agent.safe_plan import plan_safely
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.verify import Bounds, verify
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.figures import draw_world

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--scenario", default="intersection", help="a scene file or shipped name")
parser.add_argument("--head-start", type=float, default=1.0, help="how long before car 1 car 2 set off, s")
parser.add_argument("--speed", type=float, default=0.4, help="both cars' mean planned speed, m/s")
parser.add_argument("--out", type=Path, default=Path("runs/examples"), help="folder for plan_one_car.png")
args = parser.parse_args()

scene = load_scenario(args.scenario)
sdf = build_sdf(scene.world)
me, peer, safety = scene.cars[0], scene.cars[1], scene.safety


def request(car, t_now, peers=()):
    """Start at rest at t_now, arrive after the straight-line distance at --speed."""
    start, goal = np.array(car.start), np.array(car.goal)
    return PlanRequest(t_now=t_now, position=start, velocity=np.zeros(2), goal=goal,
                       t_arrive=t_now + np.linalg.norm(goal - start) / args.speed,
                       epsilon_obstacle=safety.epsilon_obstacle(car.radius_m), peers=peers,
                       route=car.route, lane=(car.start, *car.route))


theirs = plan_trajectory(request(peer, -args.head_start), scene.planner, sdf).plan
keep = PeerConstraint(theirs, safety.epsilon_0(me.radius_m, peer.radius_m))
breach = safety.breach_distance(me.radius_m, peer.radius_m)
bounds = Bounds.of(safety.epsilon_obstacle(me.radius_m), safety.obstacle_breach(me.radius_m), [breach], scene.vehicle)
alone = plan_trajectory(request(me, 0.0), scene.planner, sdf)
outcome = plan_safely(request(me, 0.0, (keep,)), bounds, scene.planner, scene.verify, sdf, last_verified=None)
print(f"car {me.id} against car {peer.id}'s plan: eps_0 {keep.epsilon:.2f} m, breach below {breach:.2f} m")
print(f"plan_safely: {outcome.outcome} after trying {', '.join(outcome.tried)}")

fig, (world, over_time) = plt.subplots(1, 2, figsize=(11, 5))
draw_world(world, scene)
times = np.linspace(0.0, max(alone.plan.t_end, outcome.plan.t_end), 500)
world.plot(*theirs.position_at(times).T, color="tab:green", lw=2, label=f"car {peer.id}'s plan")
for name, result, style in (("alone", alone, "--"), ("with peer", outcome.result, "-")):
    verdict = verify(result.plan, [keep], bounds, sdf, scene.verify)
    mine = result.plan.position_at(times)
    gap = np.linalg.norm(mine - theirs.position_at(times), axis=1)
    print(f"{name:>9}: {result.iterations} iterations, error {result.initial_error:.3f} -> "
          f"{result.final_error:.3f}, {result.time_ms:.1f} ms; closest to car {peer.id} {gap.min():.3f} m "
          f"(clearance {verdict.clearance:+.3f} m), to the walls {verdict.obstacle_clearance:+.3f} m; "
          f"verified: {verdict.ok}")
    world.plot(*mine.T, style, color="tab:blue", lw=2, label=f"car {me.id} {name}")
    over_time.plot(times, gap, style, color="tab:blue", label=f"car {me.id} {name}")
over_time.axhline(keep.epsilon, color="tab:green", ls=":", label="eps_0")
over_time.axhline(breach, color="tab:red", ls=":", label="breach")
over_time.set(xlabel="t (s)", ylabel=f"distance car {me.id} - car {peer.id} (m)", ylim=(0, None))
world.legend(loc="upper right", fontsize=8)
over_time.legend(fontsize=8)
args.out.mkdir(parents=True, exist_ok=True)
fig.savefig(args.out / "plan_one_car.png", dpi=100)
print(f"wrote {args.out / 'plan_one_car.png'}")
