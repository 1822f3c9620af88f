"""Run the in-process fleet on a scene and seed, summarise the run, draw the paths.

Every car runs the real mind (planner, verification, trust) in one process, in simulated
time, over a network with seeded latency and loss (fleet.sim.in_process.simulate); the
run repeats exactly from its seed. fleet.sim.run_record.motion_summary judges the
executed motion as every trustfg command does: arrivals, makespan, breaches, clearances.

    .venv/bin/python examples/fleet_on_a_scene.py [--scenario intersection] [--seed 0] [--out DIR]
"""

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.fleet.experiments.figures import draw_world
from trustfg.fleet.sim.in_process import simulate
from trustfg.fleet.sim.run_record import motion_summary, plan_outcomes

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--scenario", default="intersection", help="a scene file or shipped name")
parser.add_argument("--seed", type=int, default=0, help="departures, cruise speeds, noise and losses")
parser.add_argument("--out", type=Path, default=Path("runs/examples"), help="folder for fleet_on_a_scene.png")
args = parser.parse_args()

scene = load_scenario(args.scenario)
sdf = build_sdf(scene.world)
record = simulate(scene, args.seed, sdf)
summary = motion_summary(scene, record, sdf)

print(f"{scene.name}, seed {args.seed}: {len(record.car_ids)} cars, {record.times[-1]:.1f} s simulated")
for i, car_id in enumerate(record.car_ids):
    path = np.sum(np.linalg.norm(np.diff(record.states[:, i, :2], axis=0), axis=1))
    arrived = record.arrived_at[i]
    print(f"  car {car_id}: departed at {record.depart_at[i]:.2f} s, drove {path:.2f} m, "
          f"arrived {'at %.2f s' % arrived if arrived is not None else 'never'}, "
          f"replans {len(record.replan_ms[i])} (median {np.median(record.replan_ms[i]):.1f} ms)")
print(f"reached goal: {summary['reached_goal']}, makespan {summary['makespan_s']} s")
clearance = np.array(summary["min_clearance"]) + np.diag(np.full(len(record.car_ids), np.inf))
print(f"breaches: {summary['breaches'] or 'none'}; least clearance between cars {clearance.min():.3f} m, "
      f"to the walls {summary['obstacle_min_clearance']:.3f} m")
print(f"replans by outcome: {plan_outcomes(record.counters)['plans']}")

fig, ax = plt.subplots(figsize=(6, 6))
draw_world(ax, scene)
for i, (car, color) in enumerate(zip(scene.cars, scene.car_colors())):
    xy = record.states[:, i, :2]
    ax.plot(*xy.T, color=color, lw=2, label=f"car {car.id}")
    ax.plot(*car.start, "o", color=color)
    ax.plot(*car.goal, "*", color=color, ms=12)
ax.set_title(f"{scene.name}, seed {args.seed}: executed paths")
ax.legend(loc="upper right", fontsize=8)
args.out.mkdir(parents=True, exist_ok=True)
fig.savefig(args.out / "fleet_on_a_scene.png", dpi=100)
print(f"wrote {args.out / 'fleet_on_a_scene.png'}")
