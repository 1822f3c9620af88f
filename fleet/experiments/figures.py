"""Report figures in the manner of the paper (matplotlib, PNG).

* trajectories.png: each car's executed path, on and off side by side; a segment is drawn
  black where the car was, at that instant, closer to another car than the breach
  distance (paper Fig. 4: there "too close" was judged between paths; judging it at the
  same time says whether cars really came too close);
* min_distance.png: heatmaps of the min-distance matrix, on and off (Fig. 5, 8);
* acceleration.png: acceleration magnitude of every car over time (Fig. 6);
* trust.png: each car's trust in each peer over time.

The figures show one seed (the first), except min_distance.png which shows the
element-wise minimum over all seeds (the worst case).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...agent import metrics  # noqa: E402
from ...agent.config import Scenario  # noqa: E402
from ..sim.in_process import RunRecord  # noqa: E402


def draw_world(ax, scenario: Scenario) -> None:
    x0, y0, x1, y1 = scenario.world.bounds_m
    ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, lw=1.5, color="k"))
    for obstacle in scenario.world.obstacles:
        if obstacle.kind == "rect":
            (ax_, ay), (bx, by) = obstacle.min, obstacle.max
            ax.add_patch(plt.Rectangle((ax_, ay), bx - ax_, by - ay, color="0.25", alpha=0.5, lw=0))
        else:
            ax.add_patch(plt.Polygon(obstacle.points, color="0.25", alpha=0.5, lw=0))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def plot_trajectories(ax, scenario: Scenario, record: RunRecord, title: str) -> None:
    draw_world(ax, scenario)
    positions = record.states[:, :, :2]
    colors = scenario.car_colors()
    breach_distance = metrics.breach_distances(record.radii, scenario.safety.clearance_m)
    diff = positions[:, :, None, :] - positions[:, None, :, :]
    distance = np.sqrt(np.sum(diff * diff, axis=-1))
    n = positions.shape[1]
    distance[:, np.arange(n), np.arange(n)] = np.inf
    too_close = np.any(distance < breach_distance[None], axis=2)  # (T, n)
    for i in range(n):
        p = positions[:, i]
        ax.plot(p[:, 0], p[:, 1], color=colors[i], lw=2, label=f"car {record.car_ids[i]}")
        bad = too_close[:-1, i] | too_close[1:, i]
        for k in np.nonzero(bad)[0]:
            ax.plot(p[k:k + 2, 0], p[k:k + 2, 1], color="k", lw=3)
        ax.plot(*p[0], "o", color=colors[i])
        ax.plot(*scenario.cars[i].goal, "*", color=colors[i], ms=12)
    ax.set_title(title)
    ax.legend(loc="upper right", fontsize=7)


def plot_min_distance(ax, matrix: np.ndarray, ids: list[int], title: str, threshold: np.ndarray) -> None:
    """The min-distance matrix; a cell below its pair's ``threshold`` (n, n) in red."""
    shown = matrix.copy()
    np.fill_diagonal(shown, np.nan)
    image = ax.imshow(shown, cmap="viridis", vmin=0.0, vmax=max(1.2, float(np.nanmax(shown))))
    n = len(ids)
    for a in range(n):
        for b in range(n):
            if a == b:
                continue
            value, breach = matrix[a, b], matrix[a, b] < threshold[a, b]
            ax.text(b, a, f"{value:.2f}", ha="center", va="center",
                    color="red" if breach else "white", fontsize=9,
                    fontweight="bold" if breach else "normal")
            if breach:
                ax.add_patch(plt.Rectangle((b - 0.5, a - 0.5), 1, 1, fill=False, ec="red", lw=2))
    ax.set_xticks(range(n), [str(i) for i in ids])
    ax.set_yticks(range(n), [str(i) for i in ids])
    ax.set_title(title)
    plt.colorbar(image, ax=ax, fraction=0.046, label="min distance (m)")


def plot_accelerations(ax, scenario: Scenario, record: RunRecord, title: str) -> None:
    acc = metrics.accelerations(record.times, record.states)
    moving = metrics.moving_mask(record.times, record.depart_at, record.arrived_at)
    colors = scenario.car_colors()
    for i, car_id in enumerate(record.car_ids):
        ax.plot(record.times, np.where(moving[:, i], acc[:, i], np.nan), color=colors[i], label=f"car {car_id}")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("|a| (m/s²)")
    ax.set_title(title)
    ax.legend(fontsize=7)


def plot_trust(ax, scenario: Scenario, record: RunRecord, title: str) -> None:
    colors = scenario.car_colors()
    n = len(record.car_ids)
    for a in range(n):
        for b in range(n):
            if a == b:
                continue
            ax.plot(record.trust_times, record.trust[:, a, b], color=colors[b],
                    ls=["-", "--", ":", "-."][a % 4], lw=1,
                    label=f"{record.car_ids[a]}→{record.car_ids[b]}")
    ax.set_ylim(0, 1.02)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("trust τ (truster → trustee)")
    ax.set_title(title)
    ax.legend(fontsize=6, ncol=2)


def experiment_figures(name: str, scenario: Scenario, results: dict[str, list[dict]],
                       records: dict[str, list[RunRecord]], folder: Path) -> list[Path]:
    """Write the figures of one experiment; returns their paths."""
    variants = list(records)
    written = []
    threshold = metrics.breach_distances([c.radius_m for c in scenario.cars], scenario.safety.clearance_m)

    fig, axes = plt.subplots(1, len(variants), figsize=(6 * len(variants), 6))
    for ax, variant in zip(np.atleast_1d(axes), variants):
        record = records[variant][0]
        plot_trajectories(ax, scenario, record, f"{name} – {variant} (seed {record.seed})")
    written.append(_save(fig, folder / "trajectories.png"))

    fig, axes = plt.subplots(1, len(variants), figsize=(5.5 * len(variants), 4.5))
    for ax, variant in zip(np.atleast_1d(axes), variants):
        matrices = np.array([r["min_distance"] for r in results[variant]])
        plot_min_distance(ax, matrices.min(axis=0), results[variant][0]["car_ids"],
                          f"{variant}: min over {len(matrices)} seeds", threshold)
    written.append(_save(fig, folder / "min_distance.png"))

    fig, axes = plt.subplots(len(variants), 1, figsize=(9, 3.2 * len(variants)), sharex=True)
    for ax, variant in zip(np.atleast_1d(axes), variants):
        record = records[variant][0]
        run = results[variant][0]
        plot_accelerations(ax, scenario, record, f"{variant}: inconsistency {run['inconsistency']:.3f}")
    written.append(_save(fig, folder / "acceleration.png"))

    fig, axes = plt.subplots(1, len(variants), figsize=(6.5 * len(variants), 4.5), sharey=True)
    for ax, variant in zip(np.atleast_1d(axes), variants):
        plot_trust(ax, scenario, records[variant][0], f"trust – {variant}")
    written.append(_save(fig, folder / "trust.png"))
    return written


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
