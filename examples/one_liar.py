"""One liar in the paper's lab scene: how the honest cars' trust in it and the distance
they keep from it evolve.

Car ``--liar`` runs an attack (default: the paper's liar, ``--misinformation`` of its
plans displaced and false testimony; agent.config.liar_attack) and the in-process fleet
drives the scene (fleet.sim.in_process.simulate), sampling every car's trust in every
peer and the safety distance epsilon it keeps (docs/design/trust.md, "From trust to
distance"). Prints both over time and when the liar was told apart; draws them.

    .venv/bin/python examples/one_liar.py [--liar 1] [--attack false-future] [--out DIR]
"""

import argparse
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from trustfg.agent.config import liar_attack, parse_attack
from trustfg.agent.metrics import trust_detection
from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.experiments.paper import with_attack
from trustfg.fleet.sim.in_process import simulate
from trustfg.fleet.sim.trust_record import TRUST_GAP

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--scenario", default="lab", help="a scene file or shipped name")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--liar", type=int, default=1, help="the lying car's id")
parser.add_argument("--attack", help="an attack of docs/design/trust.md (default: the paper's liar)")
parser.add_argument("--misinformation", type=float, default=0.4, help="fraction of its plans that lie")
parser.add_argument("--out", type=Path, default=Path("runs/examples"), help="folder for one_liar.png")
args = parser.parse_args()

attack = liar_attack(parse_attack(args.attack) if args.attack else None, args.misinformation)
scene = with_attack(load_scenario(args.scenario), {args.liar: attack})
record = simulate(scene, args.seed)
ids = record.car_ids
liar = ids.index(args.liar)
honest = [i for i in range(len(ids)) if i != liar]


def honest_peers_mean(series: np.ndarray, a: int) -> np.ndarray:
    """Car a's mean over its honest peers of a (T, n, n) series."""
    return np.mean([series[:, a, b] for b in honest if b != a], axis=0)


print(f"{scene.name}, seed {args.seed}: car {args.liar} lies ({attack.name}, {attack.params or 'defaults'})")
print("trust in the liar vs in honest peers, and epsilon kept from the liar (t = 0: the go)")
print("  t (s)" + "".join(f"{'car %d' % ids[a]:>22}" for a in honest))
for t in np.arange(record.trust_times[0], record.trust_times[-1], 2.0):
    k = int(np.searchsorted(record.trust_times, t - 1e-9))
    print(f"  {t:5.1f}" + "".join(f"{record.trust[k, a, liar]:>8.2f} vs {honest_peers_mean(record.trust, a)[k]:.2f}, "
                                  f"{record.epsilon[k, a, liar]:.2f} m" for a in honest))
for a in honest:
    print(f"car {ids[a]} at the end: trust in the liar {record.trust[-1, a, liar]:.3f}, in honest peers "
          f"{honest_peers_mean(record.trust, a)[-1]:.3f}; epsilon from the liar {record.epsilon[-1, a, liar]:.3f} m")
found = trust_detection(record.trust_times, record.trust, liar, honest, TRUST_GAP)
print(f"told apart (every honest car trusts it {TRUST_GAP} below every honest peer) at: "
      f"{'%.1f s' % found if found is not None else 'never'}; arrived: {[a is not None for a in record.arrived_at]}")

fig, (trust_ax, eps_ax) = plt.subplots(1, 2, figsize=(11, 4.5))
for n, a in enumerate(honest):  # one line per honest car; they see much the same
    for ax, series in ((trust_ax, record.trust), (eps_ax, record.epsilon)):
        ax.plot(record.trust_times, series[:, a, liar], color="tab:red", alpha=0.7,
                label=None if n else f"honest cars -> car {args.liar}")
        ax.plot(record.trust_times, honest_peers_mean(series, a), color="tab:gray", ls="--", alpha=0.7,
                label=None if n else "honest cars -> honest peers")
trust_ax.set(xlabel="t (s, 0 = the go)", ylabel="trust", ylim=(0, 1.02), title=f"trust in car {args.liar}")
eps_ax.set(xlabel="t (s, 0 = the go)", ylabel="epsilon (m)", title="distance kept")
trust_ax.legend(fontsize=8)
args.out.mkdir(parents=True, exist_ok=True)
fig.savefig(args.out / "one_liar.png", dpi=100)
print(f"wrote {args.out / 'one_liar.png'}")
