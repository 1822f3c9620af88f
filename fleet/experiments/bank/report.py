"""What the scenario bank measured, as numbers with confidence intervals, a table and a figure.

Per scene and method, pooled over the bank's scenes and over the fresh scenes: the rate
of each outcome (success, breach, contact, deadlock, timeout); the least clearance between
two cars' edges per run (min, 5th percentile, median) and from obstacles and walls (min,
median); makespan and flowtime over successful runs; replan time (the median of each run's
median; ORCA: one RVO2 step for the fleet over the number of cars); how the replans ended
and the deadlocks the cars detected, summed; how closely the cars followed their plans (the
median and the largest of each run's 95th percentile of tracking error). 95 % intervals are percentile bootstraps
(BOOTSTRAP_RESAMPLES resamples of the runs, seeded per cell, so a report repeats); with no
event in n runs the table gives the rule-of-three upper bound 3/n instead of [0, 0].
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...sim.run_record import plan_outcomes

BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 0
OUTCOMES = ("success", "breach", "contact", "deadlock", "timeout")
GROUP_NAMES = {"bank": "bank", "fresh": "held-out"}
"""How a figure names a scene group (fleet.experiments.bank.runner: the shipped bank, and fields drawn fresh)."""


def bootstrap_ci(values, statistic, seed: int = BOOTSTRAP_SEED, resamples: int = BOOTSTRAP_RESAMPLES,
                 level: float = 0.95) -> tuple[float, float] | None:
    """Percentile bootstrap interval of ``statistic(values, axis=1)``; None without values."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return None
    rng = np.random.default_rng(seed)
    samples = values[rng.integers(0, values.size, (resamples, values.size))]
    stats = statistic(samples, axis=1)
    tail = (1.0 - level) / 2 * 100
    return float(np.percentile(stats, tail)), float(np.percentile(stats, 100 - tail))


def cell(runs: list[dict]) -> dict:
    """The summary of one group of runs (module doc)."""
    rates = {}
    for outcome in OUTCOMES:
        hits = np.array([r["outcome"] == outcome for r in runs], dtype=float)
        lo, hi = bootstrap_ci(hits, np.mean)
        rates[outcome] = [round(float(hits.mean()), 4), round(lo, 4), round(hi, 4)]
    clearance = np.array([r["least_clearance_m"] for r in runs])
    obstacle = np.array([r["obstacle_min_clearance_m"] for r in runs])
    out = {
        "runs": len(runs),
        "rates": rates,
        "least_clearance_m": {"min": _r(clearance.min()), "p5": _r(np.percentile(clearance, 5)),
                              "median": _r(np.median(clearance)), "median_ci": _ci(clearance, np.median)},
        "obstacle_clearance_m": {"min": _r(obstacle.min()), "median": _r(np.median(obstacle))},
    }
    for key in ("makespan_s", "flowtime_s", "replan_ms_median"):
        values = np.array([r[key] for r in runs if r[key] is not None and r["outcome"] == "success"]
                          if key != "replan_ms_median" else [r[key] for r in runs if r[key] is not None])
        out[key] = {"median": _r(np.median(values)) if values.size else None, "median_ci": _ci(values, np.median),
                    "runs": int(values.size)}
    p95 = [r["replan_ms_p95"] for r in runs if r.get("replan_ms_p95") is not None]
    out["replan_ms_p95_max"] = _r(max(p95)) if p95 else None
    tracking = np.array([r["tracking_error_p95_m"] for r in runs if r.get("tracking_error_p95_m") is not None])
    out["tracking_error_p95_m"] = {"median": round(float(np.median(tracking)), 4) if tracking.size else None,
                                   "max": round(float(tracking.max()), 4) if tracking.size else None}
    pipeline = plan_outcomes([r.get("counters", {}) for r in runs])  # each run's counters are its cars' sums
    replans = sum(pipeline["plans"].values())
    out["plans"] = pipeline["plans"] | {f"{k}_share": round(pipeline["plans"][k] / replans, 4) if replans else None
                                        for k in ("retry", "fallback", "kept")}
    out["deadlocks_detected"] = pipeline["deadlocks"]
    return out


def summarise(runs: list[dict]) -> list[dict]:
    """Per group (the bank, then the fresh scenes): one cell per (scene, method), then one
    per method over all the group's scenes."""
    cells = []
    keys = sorted({(r["group"], r["scene"], r["method"]) for r in runs}, key=lambda k: _order(runs, k))
    for group in dict.fromkeys(g for g, _, _ in keys):
        for _, scene, method in (k for k in keys if k[0] == group):
            chosen = [r for r in runs if (r["group"], r["scene"], r["method"]) == (group, scene, method)]
            cells.append({"group": group, "scene": scene, "method": method} | cell(chosen))
        for method in dict.fromkeys(m for g, _, m in keys if g == group):
            chosen = [r for r in runs if (r["group"], r["method"]) == (group, method)]
            scenes = len({r["scene"] for r in chosen})
            cells.append({"group": group, "scene": f"all {scenes} {group} scenes", "method": method} | cell(chosen))
    return cells


def _order(runs: list[dict], key: tuple) -> tuple:
    first = next(i for i, r in enumerate(runs) if (r["group"], r["scene"], r["method"]) == key)
    return (key[0] != "bank", first)


def _r(x) -> float:
    return round(float(x), 3)


def _ci(values: np.ndarray, statistic) -> list[float] | None:
    ci = bootstrap_ci(values, statistic)
    return None if ci is None else [_r(ci[0]), _r(ci[1])]


# --- the table ------------------------------------------------------------------------------


def markdown(report: dict) -> str:
    m = report["machine"]
    lines = [
        f"`{report['command']}` on {m['cpus']} cores ({m['cpu'] or m['platform']}): "
        + (("the journals' runs" if len(report.get("journals", ())) > 1 else "the journal's runs") + ", none run now, "
           if report["wall_time_s"] is None else f"{report['wall_time_s'] / 60:.1f} min, ")
        + f"{report['cpu_time_s'] / 60:.1f} min of CPU time in the runs"
        + (", run on " + ", ".join(f"{code} ({n})" for code, n in report["code"].items()) if report.get("code") else "")
        + (" in environments " + ", ".join(f"{env} ({n})" for env, n in report["env"].items())
           + " (fleet.experiments.run_environment)" if report.get("env") else "")
        + ".",
        "Rates in % with 95 % bootstrap intervals; 0 events in n runs: ≤ 3/n (rule of three). Clearances are "
        "between edges (m; a breach is < 0.1 between cars, a contact < 0 to an obstacle); makespan and flowtime "
        "(s) are medians over the successful runs.",
        "",
    ]
    lines += ["Runs that reached every goal safely / runs (failures: b breach, c contact, d deadlock, t timeout), "
              "least clearance between cars:", "", overview(report)]
    header = ("| scene | method | runs | success % | breach % | contact % | deadlock % | timeout % "
              "| least clearance min / median | obstacle clearance min | makespan | flowtime | replan ms "
              "| replans retried / fell back % | tracking error p95 median / max |")
    groups = list(dict.fromkeys(c["group"] for c in report["summary"]))
    for group in groups:
        lines += [f"**{'Bank scenes' if group == 'bank' else 'Fresh scenes (held out)'}**", "", header,
                  "|" + " --- |" * 14]
        for c in (c for c in report["summary"] if c["group"] == group):
            label = report["methods"].get(c["method"], {}).get("label", c["method"])
            rates = [_rate(c["rates"][o], c["runs"]) for o in OUTCOMES]
            lc = c["least_clearance_m"]
            lines.append(
                f"| {c['scene']} | {label} | {c['runs']} | " + " | ".join(rates)
                + f" | {lc['min']:.3f} / {lc['median']:.3f} | {c['obstacle_clearance_m']['min']:.3f}"
                + f" | {_median(c['makespan_s'])} | {_median(c['flowtime_s'])} | {_median(c['replan_ms_median'], 2)}"
                + f" | {_shares(c['plans'])} | {_tracking(c.get('tracking_error_p95_m'))} |")
        lines.append("")
    return "\n".join(lines)


def overview(report: dict) -> str:
    """One line per scene, one cell per method: runs that succeeded, the failures by kind
    (b breach, c contact, d deadlock, t timeout), and the least clearance between cars."""
    methods = list(report["methods"])
    lines = ["| scene | " + " | ".join(report["methods"][m]["label"] for m in methods) + " |",
             "|" + " --- |" * (len(methods) + 1)]
    scenes = list(dict.fromkeys(c["scene"] for c in report["summary"]))
    for scene in scenes:
        found = {c["method"]: c for c in report["summary"] if c["scene"] == scene}
        cells = []
        for method in methods:
            c = found.get(method)
            if c is None:
                cells.append("-")
                continue
            counts = {o: round(c["rates"][o][0] * c["runs"]) for o in OUTCOMES}
            failed = " ".join(f"{counts[o]}{o[0]}" for o in OUTCOMES[1:] if counts[o])
            cells.append(f"{counts['success']}/{c['runs']}" + (f" ({failed})" if failed else "")
                         + f", {c['least_clearance_m']['min']:.3f} m")
        lines.append(f"| {scene} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _tracking(stat: dict | None) -> str:
    """A cell's tracking error (m): the median and the largest of its runs' p95."""
    if not stat or stat["median"] is None:
        return "-"
    return f"{stat['median']:.3f} / {stat['max']:.3f}"


def _shares(plans: dict) -> str:
    if plans["retry_share"] is None:
        return "-"
    return f"{100 * plans['retry_share']:.1f} / {100 * plans['fallback_share']:.1f}"


def _rate(rate: list[float], n: int) -> str:
    p, lo, hi = (100 * x for x in rate)
    if p == 0:
        return f"0 (≤ {min(100.0, 300 / n):.1f})"  # the rule of three, never above 100 %
    return f"{p:.1f} [{lo:.1f}, {hi:.1f}]"


def _median(stat: dict, digits: int = 1) -> str:
    if stat["median"] is None:
        return "-"
    ci = stat["median_ci"]
    return f"{stat['median']:.{digits}f} [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


# --- the figure -------------------------------------------------------------------------------


def figure(report: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cells = [c for c in report["summary"] if c["group"] == "bank" and not c["scene"].startswith("all ")]
    cells += [c for c in report["summary"] if c["group"] == "fresh" and c["scene"].startswith("all ")]
    scenes = list(dict.fromkeys(c["scene"] for c in cells))
    methods = list(dict.fromkeys(c["method"] for c in cells))
    labels = [s if not s.startswith("all ") else "fresh (held out)" for s in scenes]
    width = 0.8 / len(methods)
    colors = {"full": "tab:blue", "fixed": "tab:orange", "wide": "tab:green", "orca": "tab:red"}
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(max(10, 1.1 * len(scenes)), 8), sharex=True)
    rng = np.random.default_rng(0)
    for k, method in enumerate(methods):
        label = report["methods"].get(method, {}).get("label", method)
        x = np.arange(len(scenes)) + (k - (len(methods) - 1) / 2) * width
        found = {c["scene"]: c for c in cells if c["method"] == method}
        rate = np.array([100 * found[s]["rates"]["success"][0] if s in found else np.nan for s in scenes])
        lo = np.array([100 * found[s]["rates"]["success"][1] if s in found else np.nan for s in scenes])
        hi = np.array([100 * found[s]["rates"]["success"][2] if s in found else np.nan for s in scenes])
        top.bar(x, rate, width, color=colors.get(method), label=label, yerr=[rate - lo, hi - rate], capsize=2)
        for i, scene in enumerate(scenes):
            group = "fresh" if scene.startswith("all ") else "bank"
            values = [r["least_clearance_m"] for r in report["runs"] if r["method"] == method
                      and (r["scene"] == scene if group == "bank" else r["group"] == "fresh")]
            bottom.scatter(x[i] + rng.uniform(-width / 3, width / 3, len(values)), values, s=10,
                           color=colors.get(method), alpha=0.6, lw=0)
    top.set_ylabel("success (%), 95 % CI")
    top.set_ylim(0, 105)
    top.legend(fontsize=8, ncol=len(methods), loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    bottom.axhline(0.1, color="k", lw=1, ls="--", label="required clearance (breach below)")
    bottom.axhline(0.0, color="r", lw=1, label="contact")
    bottom.set_ylabel("least clearance per run (m)")
    bottom.legend(fontsize=8, loc="upper right")
    bottom.set_xticks(np.arange(len(scenes)), labels, rotation=30, ha="right")
    fig.suptitle(f"scenario bank: {seeds_per_scene(report)}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def seeds_per_scene(report: dict) -> str:
    """The figure's title: "100 seeds per bank scene, 5 per held-out scene"."""
    counts: dict[str, set[int]] = {}
    for scene in report["scenes"].values():
        counts.setdefault(scene["group"], set()).add(len(scene["seeds"]))
    parts = []
    for k, (group, n) in enumerate(sorted(counts.items())):
        unit = "" if k else " seed" if n == {1} else " seeds"
        parts.append(f"{'/'.join(map(str, sorted(n)))}{unit} per {GROUP_NAMES.get(group, group)} scene")
    return ", ".join(parts)
