"""Read a recorded run: what was said, by whom, and where the cars drove.

``trustfg sim`` records every run to RUN/run.mcap (MCAP; ``trustfg record`` records a
live fleet the same way). fleet.recording.mcap_file.read_recording gives back the fleet
config that ran and every fleet message in log-time order, as plain dicts (the keys of
agent.messages.to_dict). This counts the messages, measures each car's path from the
ground truth (else from the poses the cars published), prints each car's last word on
its peers' trust, and draws the paths.

    .venv/bin/python examples/read_a_recording.py [RUN or RUN/run.mcap] [--out DIR]

Without a path it reads the newest runs/sim-*/run.mcap.
"""

import argparse
from collections import Counter, defaultdict
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trustfg.fleet.experiments.figures import draw_world
from trustfg.fleet.recording.mcap_file import read_recording, resolve_run

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("run", type=Path, nargs="?", help="a run folder or an .mcap file (default: the newest runs/sim-*)")
parser.add_argument("--out", type=Path, default=Path("runs/examples"), help="folder for read_a_recording.png")
args = parser.parse_args()

run = args.run or max(Path("runs").glob("sim-*/run.mcap"), key=lambda p: p.stat().st_mtime, default=None)
if run is None:
    parser.error("no runs/sim-*/run.mcap here: run trustfg sim first, or name a recording")
scene, events = read_recording(resolve_run(run))
ids = [car.id for car in scene.cars]
print(f"{run}: {scene.name}, cars {ids}, {len(events)} messages over {events[-1].at - events[0].at:.1f} s")
print("messages by kind:", dict(Counter(e.kind for e in events)))

paths = defaultdict(list)  # car id -> [(x, y), ...]
truth = [e for e in events if e.kind == "truth"]
source = "ground truth" if truth else "published poses"
for e in truth:
    for car, state in e.data["cars"].items():
        paths[int(car)].append((state["x"], state["y"]))
for e in events if not truth else ():
    if e.kind == "pose" and e.data["valid"]:
        paths[e.sender].append((e.data["x"], e.data["y"]))
last_trust = {e.sender: e.data["peers"] for e in events if e.kind == "trust"}
for car in ids:
    xy = np.array(paths[car]).reshape(-1, 2)
    length = np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))
    to_goal = np.linalg.norm(xy[-1] - scene.car(car).goal) if len(xy) else float("nan")
    trust = ", ".join(f"{peer}: {entry['trust']:.2f}" for peer, entry in sorted(last_trust.get(car, {}).items()))
    print(f"  car {car}: drove {length:.2f} m ({source}), ends {to_goal:.2f} m from its goal; "
          f"last trust in its peers {{{trust or 'none reported'}}}")

fig, ax = plt.subplots(figsize=(6, 6))
draw_world(ax, scene)
for car, color in zip(scene.cars, scene.car_colors()):
    if paths[car.id]:
        ax.plot(*np.array(paths[car.id]).T, color=color, lw=2, label=f"car {car.id}")
    ax.plot(*car.goal, "*", color=color, ms=12)
ax.set_title(f"{scene.name}: paths from the {source}")
ax.legend(loc="upper right", fontsize=8)
args.out.mkdir(parents=True, exist_ok=True)
fig.savefig(args.out / "read_a_recording.png", dpi=100)
print(f"wrote {args.out / 'read_a_recording.png'}")
