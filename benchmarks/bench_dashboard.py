"""Is the dashboard smooth at 10 Hz with 8 cars?

    python benchmarks/bench_dashboard.py [--seconds 20]

Runs an 8-car ``trustfg sim`` (which records it), then replays the recording in the
dashboard and opens the page in headless Chromium for ``--seconds``: reports the rate at
which snapshots reached the page and how long the page took to draw one (median, p99,
max; a frame at 60 Hz is 16.7 ms).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.launch.launcher import default_scenario, free_port, loopback_fleet, run

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]


def main() -> None:
    from playwright.sync_api import sync_playwright

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        run(loopback_fleet(load_scenario(default_scenario(8)), 8, None, 0.0), out, seed=0)
        port = free_port()
        server = subprocess.Popen([sys.executable, "-m", "trustfg", "dashboard", "--replay", str(out),
                                   "--port", str(port)], stdout=subprocess.DEVNULL)
        try:
            for _ in range(100):
                try:
                    urllib.request.urlopen(f"http://127.0.0.1:{port}/api/map", timeout=1)
                    break
                except OSError:
                    time.sleep(0.1)
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=shutil.which("chromium"), args=FLAGS)
                page = browser.new_page(viewport={"width": 1500, "height": 900})
                page.goto(f"http://127.0.0.1:{port}/")
                page.wait_for_selector("circle.car-body[data-x]")
                start = page.evaluate("window.trustfgStats.snapshots")
                page.wait_for_timeout(int(args.seconds * 1000))
                stats = page.evaluate("window.trustfgStats")
                browser.close()
        finally:
            server.terminate()
            server.wait(10)
    ms = np.array(stats["renderMs"])
    print(f"8 cars: {(stats['snapshots'] - start) / args.seconds:.1f} snapshots/s reached the page; "
          f"draw time median {np.median(ms):.2f} ms, p99 {np.percentile(ms, 99):.2f} ms, max {ms.max():.2f} ms "
          f"({len(ms)} frames)")


if __name__ == "__main__":
    main()
