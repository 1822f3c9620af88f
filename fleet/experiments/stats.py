"""Summaries of many seeds with 95 % confidence intervals (seeded percentile bootstrap).

A cell of an experiment's table is the runs of one (scene, attack, variant) over many
seeds; :func:`cell` reduces them to the numbers the tables print, each with its interval:
``breach_rate`` (seeds with an honest-liar breach), ``min_clearance_m`` (least honest-liar
clearance, and its median), ``detected_3s_rate`` (of the seeds in which the liar lied
beyond ``plan_reject_m``, those in which every honest car trusted it 0.2 below every honest
peer within DETECTION_LIMIT_S of its first lie coming due; ``detected_3s_told_rate`` timed
from the telling), ``withdrawn`` (lies that never came due), ``detection_s`` (median delay),
``false_positive_rate`` (an honest car's trust in an honest peer below FALSE_POSITIVE_TRUST
after the first 3 s) and ``makespan_s``. Intervals: RESAMPLES resamples of the seeds with a
fixed generator, so a rerun prints the same. docs/design/experiments.md, "Statistics".
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

RESAMPLES = 2000
LEVEL = 0.95
FALSE_POSITIVE_TRUST = 0.8
DETECTION_LIMIT_S = 3.0


def least_pair_clearance(run: dict) -> float:
    """The least clearance between two different cars of a run (its ``min_clearance``
    matrix without the diagonal, which is each car with itself)."""
    return min(c for i, row in enumerate(run["min_clearance"]) for j, c in enumerate(row) if i != j)


def bootstrap_ci(values: Sequence[float], statistic: Callable = np.median, seed: int = 0) -> tuple[float, float] | None:
    """The percentile bootstrap interval of ``statistic`` (a numpy reduction taking
    ``axis``) over ``values``; None if empty."""
    data = np.asarray([v for v in values if v is not None], dtype=float)
    if len(data) == 0:
        return None
    rng = np.random.default_rng(seed)
    samples = rng.choice(data, size=(RESAMPLES, len(data)), replace=True)
    stats = statistic(samples, axis=1)
    tail = 100 * (1 - LEVEL) / 2
    return float(np.percentile(stats, tail)), float(np.percentile(stats, 100 - tail))


def estimate(values: Sequence[float], statistic: Callable = np.median) -> dict | None:
    """{"value", "ci": [lo, hi], "n"} of a statistic over the non-None values."""
    data = [v for v in values if v is not None]
    if not data:
        return None
    low, high = bootstrap_ci(data, statistic)
    return {"value": round(float(statistic(np.asarray(data, dtype=float))), 4),
            "ci": [round(low, 4), round(high, 4)], "n": len(data)}


def rate(flags: Sequence[bool]) -> dict:
    """The fraction of True with its bootstrap interval."""
    return estimate([1.0 if f else 0.0 for f in flags], np.mean) or {"value": None, "ci": None, "n": 0}


def cell(runs: list[dict]) -> dict:
    """The table's numbers for the runs of one cell (RUN dicts of fleet.experiments.paper)."""
    liar = "liar_id" in runs[0]
    # With limited sight (fleet.experiments.testimony), of the peers seen a while: the others are unknown.
    key = "honest_trust_min_in_sight" if "honest_trust_min_in_sight" in runs[0] else "honest_trust_min_after_settle"
    honest_min = [r[key] for r in runs if r.get(key) is not None]
    out = {
        "runs": len(runs),
        "breach_seeds_any": sum(1 for r in runs if r["breaches"]),
        "all_arrived": sum(1 for r in runs if all(r["reached_goal"])),
        "makespan_s": estimate([r["makespan_s"] for r in runs]),
        "false_positive_rate": rate([t < FALSE_POSITIVE_TRUST for t in honest_min]),
        "honest_trust_min": round(min(honest_min), 4) if honest_min else None,
    }
    if not liar:
        out["min_clearance_m"] = round(min(least_pair_clearance(r) for r in runs), 4)
        return out
    lied = [r for r in runs if r.get("first_lie_s") is not None]
    delays = [r.get("detection_delay_s") for r in lied]
    out |= {
        "breach_rate": rate([bool(r["liar_breaches"]) for r in runs]),
        "breach_seeds": sum(1 for r in runs if r["liar_breaches"]),
        "min_clearance_m": round(min(r["liar_min_clearance"] for r in runs), 4),
        "median_clearance_m": estimate([r["liar_min_clearance"] for r in runs]),
        "lied_beyond_tolerance": len(lied),
        "detected_3s_rate": rate([d is not None and d <= DETECTION_LIMIT_S for d in delays]),
        "detected_3s_told_rate": rate([d is not None and d <= DETECTION_LIMIT_S
                                       for d in (r.get("detection_after_told_s") for r in lied)]),
        "withdrawn": sum(1 for r in lied if r.get("first_lie_due_s") is None),
        "detection_s": estimate(delays),
        "never_detected": sum(1 for d in delays if d is None),
        "liar_distance_m": estimate([d for r in runs for d in r["liar_min_distance"]]),
    }
    return out


def show(estimated: dict | None, digits: int = 2, percent: bool = False) -> str:
    """``value [lo, hi]`` for a table."""
    if not estimated or estimated.get("value") is None:
        return "-"
    scale = 100.0 if percent else 1.0
    unit = " %" if percent else ""
    value, (low, high) = estimated["value"] * scale, estimated["ci"]
    return f"{value:.{digits}f} [{low * scale:.{digits}f}, {high * scale:.{digits}f}]{unit}"


def markdown(title: str, header: list[str], rows: list[list[str]]) -> str:
    """A titled markdown table."""
    lines = [f"#### {title}", "", "| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in rows]
    return "\n".join(lines) + "\n"
