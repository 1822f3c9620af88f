"""``trustfg report RUN``: the experiments' figures and an HTML page, from a recording.

RUN is a ``trustfg sim`` run folder (its run.mcap) or any .mcap recording. Motion comes
from the recorded ground truth when there is one, else from the poses the cars
published; trust over time from the trust reports. Writes, next to the recording
(or into ``--out``): trajectories.png, min_distance.png, acceleration.png, trust.png and
report.html, which puts them together with the summary tables.
"""

from __future__ import annotations

import html
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

from ..agent import metrics
from ..agent.world import build_sdf
from ..fleet.experiments import figures
from ..fleet.program import command_parser
from ..fleet.recording.mcap_file import read_recording, resolve_run
from ..fleet.sim.run_record import RunRecord, arrivals, motion_summary, rounded

TRUST_SAMPLE_S = 0.1


def record_from(path: Path) -> tuple:
    """(scenario, RunRecord) rebuilt from a recording."""
    scenario, events = read_recording(path)
    ids = [c.id for c in scenario.cars]
    truth = [e for e in events if e.kind == "truth"]
    if truth:
        times = np.array([e.at for e in truth])
        states = np.array([[[e.data["cars"][str(i)][k] for k in ("x", "y", "yaw", "v", "omega")] for i in ids]
                           for e in truth])
    else:
        times, states = _states_from_poses(events, ids)
    start = next((e for e in events if e.kind == "start"), None)
    t0 = min(c["depart"] for c in start.data["cars"].values()) if start else times[0]
    depart = [start.data["cars"][str(i)]["depart"] - t0 if start and str(i) in start.data["cars"] else 0.0 for i in ids]
    rel = times - t0
    arrived = arrivals(scenario, rel, states)
    trust_times, trust, transparency, epsilon = _trust_series(events, ids, t0)
    replan = defaultdict(list)
    for e in events:
        if e.kind == "status" and e.data.get("replan_ms"):
            replan[e.data["id"]].append(e.data["replan_ms"])
    record = RunRecord(seed=-1, car_ids=ids, radii=[c.radius_m for c in scenario.cars], times=rel, states=states,
                       arrived_at=arrived, depart_at=depart, trust_times=trust_times, trust=trust,
                       transparency=transparency, epsilon=epsilon, replan_ms=[replan[i] for i in ids],
                       counters=[{} for _ in ids], inbox=[{} for _ in ids])
    return scenario, record


def _states_from_poses(events, ids):
    index = {i: k for k, i in enumerate(ids)}
    poses = [e for e in events if e.kind == "pose" and e.data.get("valid") and e.data["id"] in index]
    if not poses:
        raise ValueError("the recording holds neither ground truth nor valid poses")
    times = np.arange(poses[0].at, poses[-1].at, 0.02)
    states = np.full((len(times), len(ids), 5), np.nan)
    for k, i in enumerate(ids):
        mine = [(e.at, e.data["x"], e.data["y"], e.data["yaw"]) for e in poses if e.data["id"] == i]
        if not mine:
            continue
        a = np.array(mine)
        for column, values in ((0, a[:, 1]), (1, a[:, 2]), (2, np.unwrap(a[:, 3]))):
            states[:, k, column] = np.interp(times, a[:, 0], values)
        speed = np.gradient(states[:, k, :2], times, axis=0)
        states[:, k, 3] = np.linalg.norm(speed, axis=1)
        states[:, k, 4] = np.gradient(states[:, k, 2], times)
    return times, np.nan_to_num(states)


def _trust_series(events, ids, t0):
    index = {i: k for k, i in enumerate(ids)}
    n = len(ids)
    reports = [e for e in events if e.kind == "trust" and e.data["id"] in index]
    if not reports:
        return np.zeros(1), np.ones((1, n, n)), np.ones((1, n, n)), np.zeros((1, n, n))
    grid = np.arange(reports[0].at, reports[-1].at + TRUST_SAMPLE_S, TRUST_SAMPLE_S)
    trust = np.ones((len(grid), n, n))
    transparency = np.ones((len(grid), n, n))
    epsilon = np.zeros((len(grid), n, n))
    current_t = np.ones((n, n))
    current_tr = np.ones((n, n))
    current_e = np.zeros((n, n))
    k = 0
    for g, t in enumerate(grid):
        while k < len(reports) and reports[k].at <= t:
            a = index[reports[k].data["id"]]
            for peer, entry in reports[k].data["peers"].items():
                if int(peer) in index:
                    b = index[int(peer)]
                    current_t[a, b], current_tr[a, b], current_e[a, b] = entry["trust"], entry["tau"][2], entry["epsilon"]
            k += 1
        trust[g], transparency[g], epsilon[g] = current_t, current_tr, current_e
    return grid - t0, trust, transparency, epsilon


def run_summary(scenario, record: RunRecord) -> dict:
    return motion_summary(scenario, record, build_sdf(scenario.world)) | {"trust": rounded(record.trust[-1])}


def write_report(run: Path, out: Path | None = None) -> Path:
    path = resolve_run(run)
    folder = out or path.parent
    folder.mkdir(parents=True, exist_ok=True)
    scenario, record = record_from(path)
    summary = run_summary(scenario, record)
    run_json = path.parent / "summary.json"
    if run_json.exists():  # a trustfg sim run: its own summary has more (replan times, messages)
        summary = json.loads(run_json.read_text()) | {"inconsistency": summary["inconsistency"]}
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    figures.plot_trajectories(ax, scenario, record, f"{scenario.name}: executed paths (too close: black)")
    figures._save(fig, folder / "trajectories.png")
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    threshold = metrics.breach_distances(record.radii, scenario.safety.clearance_m)
    figures.plot_min_distance(ax, np.array(summary["min_distance"]), record.car_ids, "min distance (m)", threshold)
    figures._save(fig, folder / "min_distance.png")
    fig, ax = plt.subplots(figsize=(9, 3.5))
    figures.plot_accelerations(ax, scenario, record, f"acceleration, inconsistency {summary['inconsistency']:.3f}")
    figures._save(fig, folder / "acceleration.png")
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    figures.plot_trust(ax, scenario, record, "trust over time")
    figures._save(fig, folder / "trust.png")
    page = folder / "report.html"
    page.write_text(_html(scenario, summary))
    return page


def _matrix_table(ids, matrix, fmt="{:.2f}", low=None) -> str:
    head = "".join(f"<th>{i}</th>" for i in ids)
    rows = []
    for a, row in zip(ids, matrix):
        cells = []
        for b, value in zip(ids, row):
            text = "·" if a == b else ("–" if value is None else fmt.format(value))
            flag = ' class="low"' if low is not None and a != b and value is not None and value < low else ""
            cells.append(f"<td{flag}>{text}</td>")
        rows.append(f"<tr><th>{a}</th>{''.join(cells)}</tr>")
    return f"<table><tr><th></th>{head}</tr>{''.join(rows)}</table>"


def _html(scenario, summary: dict) -> str:
    ids = summary["car_ids"]
    facts = [("scenario", scenario.name), ("cars", ", ".join(map(str, ids))),
             ("breaches (clearance < 0.1 m)", summary["breaches"] or "none"),
             ("every car reached its goal", all(summary["reached_goal"])),
             ("makespan", f"{summary['makespan_s']} s"),
             ("obstacle clearance", f"{summary['obstacle_min_clearance']} m"),
             ("inconsistency index", summary["inconsistency"])]
    if "crashed" in summary:
        facts.append(("crashed processes", summary["crashed"] or "none"))
    rows = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in facts)
    replan = ""
    if "replan_ms" in summary:
        replan = "<h2>Replanning and commands</h2><table><tr><th>car</th><th>replans</th><th>median ms</th>" \
                 "<th>p95 ms</th><th>commands Hz</th><th>jitter p99 ms</th></tr>" + "".join(
                     f"<tr><th>{car}</th><td>{(r or {}).get('count', '–')}</td><td>{(r or {}).get('median', '–')}</td>"
                     f"<td>{(r or {}).get('p95', '–')}</td><td>{((summary.get('control') or {}).get(car) or {}).get('rate_hz', '–')}</td>"
                     f"<td>{((summary.get('control') or {}).get(car) or {}).get('jitter_ms_p99', '–')}</td></tr>"
                     for car, r in summary["replan_ms"].items()) + "</table>"
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>trustfg report: {html.escape(scenario.name)}</title>
<style>body{{font-family:system-ui,sans-serif;margin:2em;max-width:70em}}table{{border-collapse:collapse;margin:.5em 0}}
td,th{{border:1px solid #ccc;padding:.2em .6em;text-align:right}}.low{{background:#ffcdd2}}img{{max-width:100%}}
.figs{{display:grid;grid-template-columns:1fr 1fr;gap:1em}}</style></head><body>
<h1>trustfg report: {html.escape(scenario.name)}</h1>
<table>{rows}</table>
<h2>Minimum distance (m, centre to centre)</h2>{_matrix_table(ids, summary['min_distance'], low=0.3)}
<h2>Trust at the end (row trusts column)</h2>{_matrix_table(ids, summary['trust'], low=0.6)}
{replan}
<h2>Figures</h2><div class="figs">
<img src="trajectories.png" alt="trajectories"><img src="min_distance.png" alt="min distance">
<img src="acceleration.png" alt="acceleration"><img src="trust.png" alt="trust"></div>
</body></html>"""


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg report", __doc__)
    parser.add_argument("run", type=Path, help="a trustfg sim run folder or an .mcap recording")
    parser.add_argument("--out", type=Path, default=None, help="where to write (default: next to the recording)")
    args = parser.parse_args(argv)
    try:
        page = write_report(args.run, args.out)
    except (OSError, ValueError) as exc:
        print(f"trustfg report: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {page}")
    return 0
