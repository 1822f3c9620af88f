"""Soak: a 4-car ``trustfg sim`` driving laps for half an hour; does anything grow?

    python benchmarks/bench_soak.py [--minutes 30] [--interval 10] [--out DIR]

Starts ``trustfg sim --laps 100000`` (four car processes, the dashboard, the launcher
recording every message) and samples every process of the run from /proc every
``--interval`` seconds: resident memory, open file descriptors, threads and CPU time, and
the whole machine's busy time, so load from outside the run is told apart. Verdicts per
process, from the end of the first minute after the go: RSS growth at most 5 %, fd growth
at most 0, and (car processes, from their ``late_ms_p99_by_minute``) tick lateness p99 of
the last 5 minutes no more than 1 ms or 25 % worse than minutes 2-6. Prints a table,
writes DIR/soak.json and exits 0 when every verdict holds. Run it alone on the machine.
Results: docs/results/performance.md#soak.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

RSS_GROWTH_MAX = 0.05
LATE_SLACK_MS = 1.0
LATE_SLACK_REL = 0.25


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (children of children ...), from /proc/PID/task/*/children."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{parent}/task")
        except OSError:
            continue
        for task in tasks:
            try:
                children = Path(f"/proc/{parent}/task/{task}/children").read_text().split()
            except OSError:
                continue
            for child in map(int, children):
                found.append(child)
                todo.append(child)
    return found


def role(pid: int) -> str | None:
    """Which trustfg process this is: 'sim', 'mocap-sim', 'car 3', 'dashboard' (None: not ours)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
    except OSError:
        return None
    if "trustfg" not in argv:
        return None
    rest = argv[argv.index("trustfg") + 1:]
    if rest and rest[0] == "car":
        return f"car {rest[rest.index('--id') + 1]}"
    return rest[0] if rest else None


TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def sample(pid: int) -> dict | None:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        stat = Path(f"/proc/{pid}/stat").read_text()
        fds = len(os.listdir(f"/proc/{pid}/fd"))
    except OSError:
        return None
    fields = dict(line.split(":", 1) for line in status.splitlines() if ":" in line)
    utime, stime = map(int, stat.rsplit(")", 1)[1].split()[11:13])  # fields 14 and 15 of proc(5)
    return {"rss_kb": int(fields["VmRSS"].split()[0]), "fds": fds, "threads": int(fields["Threads"]),
            "cpu_s": round((utime + stime) * TICK_S, 2)}


def machine_busy_s() -> float:
    """CPU seconds the whole machine spent busy (all cores), from /proc/stat."""
    values = list(map(int, Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]))
    idle = values[3] + values[4]  # idle, iowait
    return (sum(values[:8]) - idle) * TICK_S


def at(samples: list[dict], t: float) -> dict:
    """The first sample at or after t seconds."""
    return next((s for s in samples if s["t"] >= t), samples[-1])


def verdicts(series: dict[str, list[dict]], cars: dict[str, dict], minutes: float) -> tuple[list[str], bool]:
    lines = [f"{'process':<10} {'RSS @1min MB':>12} {'RSS end MB':>10} {'growth':>7} {'fds @1min':>9} "
             f"{'fds end':>7} {'threads':>7} {'late p99 min2-6 ms':>18} {'last 5 min ms':>13}"]
    ok = True
    for name, samples in sorted(series.items()):
        first, last = at(samples, 60.0), samples[-1]
        growth = (last["rss_kb"] - first["rss_kb"]) / first["rss_kb"]
        fd_growth = last["fds"] - first["fds"]
        late_early = late_late = "-"
        late_ok = True
        minutes_p99 = (cars.get(name) or {}).get("late_ms_p99_by_minute") or []
        if len(minutes_p99) >= 11:
            early, late = max(minutes_p99[1:6]), max(minutes_p99[-5:])
            late_early, late_late = f"{early:.2f}", f"{late:.2f}"
            late_ok = late <= early + max(LATE_SLACK_MS, LATE_SLACK_REL * early)
        elif name.startswith("car"):
            late_ok = False
        good = growth <= RSS_GROWTH_MAX and fd_growth <= 0 and late_ok
        ok &= good
        verdict = "" if good else ("   <-- run too short for the lateness verdict" if late_early == "-"
                                   else "   <-- grows")
        lines.append(f"{name:<10} {first['rss_kb'] / 1024:>12.1f} {last['rss_kb'] / 1024:>10.1f} {growth:>+7.1%} "
                     f"{first['fds']:>9} {last['fds']:>7} {last['threads']:>7} {late_early:>18} {late_late:>13}"
                     + verdict)
    return lines, ok


def load_by_window(series: dict[str, list[dict]], machine: list[dict], window_s: float = 300.0) -> list[str]:
    """Per 5 minutes: CPU the run's processes used and what the whole machine used (in cores):
    more busy than ours is someone else's load, which shows up as lateness."""
    lines = [f"{'minutes':>9} {'ours (cores)':>12} {'machine (cores)':>15}"]
    start = 0.0
    while start + window_s <= machine[-1]["t"] + 1e-9:
        a, b = at(machine, start), at(machine, start + window_s)
        span = max(b["t"] - a["t"], 1e-9)
        ours = sum(at(v, start + window_s)["cpu_s"] - at(v, start)["cpu_s"] for v in series.values())
        lines.append(f"{start / 60:>4.0f}-{(start + window_s) / 60:<4.0f} {ours / span:>12.2f} "
                     f"{(b['busy_s'] - a['busy_s']) / span:>15.2f}")
        start += window_s
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="how long the cars drive (default 30)")
    parser.add_argument("--interval", type=float, default=10.0, help="seconds between samples (default 10)")
    parser.add_argument("--out", type=Path, default=Path("runs") / time.strftime("soak-%Y%m%d-%H%M%S"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    sim = subprocess.Popen([sys.executable, "-m", "trustfg", "sim", "--laps", "100000", "--timeout",
                            str(args.minutes * 60), "--out", str(args.out / "run"), "--dashboard-port", "0"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    for line in sim.stdout:  # wait for the go; the cars are up
        print(line, end="", flush=True)
        if "go (seed" in line:
            break
    t0 = time.monotonic()
    series: dict[str, list[dict]] = {}
    try:
        while sim.poll() is None and time.monotonic() - t0 < args.minutes * 60 - 5:
            t = time.monotonic() - t0
            series.setdefault("machine", []).append({"t": round(t, 1), "busy_s": round(machine_busy_s(), 2)})
            for pid in [sim.pid, *descendants(sim.pid)]:
                name = "sim" if pid == sim.pid else role(pid)
                if name is not None and (s := sample(pid)) is not None:
                    series.setdefault(name, []).append({"t": round(t, 1)} | s)
            if int(t) % 300 < args.interval:
                print(f"soak: {t / 60:5.1f} min, " + ", ".join(
                    f"{n} {v[-1]['rss_kb'] / 1024:.0f} MB/{v[-1]['fds']} fds" for n, v in sorted(series.items())
                    if n != "machine"), flush=True)
            time.sleep(max(0.0, args.interval - (time.monotonic() - t0 - t)))
        for line in sim.stdout:  # the launcher stops everything and summarises
            pass
        sim.wait(timeout=1800)
    finally:
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGTERM)
            sim.wait(timeout=30)
    cars = {}
    for path in (args.out / "run").glob("car_*.json"):
        cars[f"car {path.stem.split('_')[1]}"] = json.loads(path.read_text()).get("control", {})
    machine = series.pop("machine")
    lines, ok = verdicts(series, cars, args.minutes)
    lines += load_by_window(series, machine)
    (args.out / "soak.json").write_text(json.dumps({"minutes": args.minutes, "series": series, "cars": cars}))
    print("\n".join(lines))
    summary = json.loads((args.out / "run" / "summary.json").read_text())
    print(f"breaches: {summary['breaches'] or 'none'}; crashed: {summary['crashed'] or 'none'}; "
          f"laps: {dict((k, v.get('lap')) for k, v in _last_laps(args.out / 'run').items())}")
    print("no growth" if ok else "something grows")
    return 0 if ok else 1


def _last_laps(run: Path) -> dict[str, dict]:
    """Each car's last status counters (its lap), from the launcher's message log."""
    last: dict[str, dict] = {}
    with open(run / "messages.jsonl") as f:
        for line in f:
            if '"status"' in line and '"message"' in line:
                record = json.loads(line)
                last[str(record["sender"])] = record["message"]["counters"]
    return last


if __name__ == "__main__":
    raise SystemExit(main())
