"""The dashboard in a real browser (Debian's headless Chromium, driven by Playwright)
against a live 4-car ``trustfg sim`` with a liar; then the run's recording.

Screenshots are kept in test-artifacts/ at the repository root.
"""

import json
import shutil
import threading
import time
import urllib.request
from collections import defaultdict, deque

import numpy as np
import pytest

from tests.conftest import ROOT, wait_for
from trustfg.agent import messages
from trustfg.dashboard.server import replay_to_end
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.launcher import loopback_fleet, run
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.recording.mcap_file import read_recording

pytestmark = pytest.mark.browser

ARTIFACTS = ROOT / "test-artifacts"
HEARD_FOR_S = 1.0  # the page is compared with what the test heard over at least this long
CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def chromium() -> str:
    path = shutil.which("chromium")
    if path is None:
        raise RuntimeError("Debian's chromium is not installed: run tests/setup-system.sh as root")
    return path


class Published:
    """What the cars publish, as the test itself hears it on the bus."""

    def __init__(self, fleet):
        self.bus = FleetBus(fleet.bus, fleet.fleet, None, listen=(f"tcp/127.0.0.1:{free_port()}",))
        self.inbox = messages.Inbox()
        self.poses = defaultdict(lambda: deque(maxlen=100))
        self.trust = defaultdict(lambda: deque(maxlen=20))

    def poll(self):
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            if isinstance(message, messages.PoseMessage) and message.valid:
                self.poses[message.sender].append((received.at, message.x, message.y))
            elif isinstance(message, messages.TrustReport):
                for peer, pt in message.peers.items():
                    self.trust[(message.sender, peer)].append((received.at, pt.trust))


@pytest.fixture(scope="module")
def live_run(intersection, tmp_path_factory):
    fleet = loopback_fleet(intersection, None, 1, 0.4)
    out = tmp_path_factory.mktemp("dashboard-run")
    port = free_port()
    result = {}

    def launch():
        try:
            result["summary"] = run(fleet, out, seed=21, dashboard_port=port)
        except BaseException as exc:  # told by the test that waits for the page, not lost in a thread
            result["error"] = exc
            raise

    thread = threading.Thread(target=launch, daemon=True)
    published = Published(fleet)
    published.bus.open()
    thread.start()
    yield fleet, out, port, published, thread, result
    published.bus.close()
    thread.join(timeout=180)


def page_up(port):
    try:
        return urllib.request.urlopen(f"http://127.0.0.1:{port}/api/map", timeout=1).status == 200
    except OSError:
        return False


def why_not_up(out, thread, result) -> str:
    """What there is to say when the run's dashboard never answered: the run's error, or
    the end of the dashboard's log."""
    log = out / "dashboard.log"
    tail = log.read_text(errors="replace").splitlines()[-15:] if log.exists() else ["(no dashboard.log)"]
    return (f"the dashboard did not come up; the run {'ended' if not thread.is_alive() else 'is running'}"
            f"{', raising ' + repr(result['error']) if 'error' in result else ''}; dashboard.log ends:\n"
            + "\n".join(tail))


def test_the_live_page_draws_the_published_poses_trust_and_alerts(live_run):
    from playwright.sync_api import sync_playwright

    fleet, out, port, published, thread, result = live_run
    ARTIFACTS.mkdir(exist_ok=True)
    assert wait_for(lambda: page_up(port) or not thread.is_alive(), 60.0) and page_up(port), \
        why_not_up(out, thread, result)
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium(), args=CHROMIUM_FLAGS)
        try:
            page = browser.new_page(viewport={"width": 1500, "height": 900})
            page.goto(f"http://127.0.0.1:{port}/")
            page.wait_for_selector("#connection[data-state='connected']", timeout=20000)
            page.wait_for_function("document.querySelectorAll('circle.car-body[data-x]').length === 4", timeout=60000)
            # The test's own session joins the cars by connecting to their endpoints; they
            # start after it, so it hears them only once Zenoh's connect retry gets through.
            def heard_every_car():
                published.poll()
                return all(published.poses[car.id] for car in fleet.cars)
            t0 = time.monotonic()
            assert wait_for(heard_every_car, 30.0), f"the test heard poses only from {sorted(published.poses)}"
            print(f"the test's session heard every car {time.monotonic() - t0:.1f} s after the page drew them")
            # Positions: every drawn car sits where that car recently said it is -- once the
            # test has heard the car for HEARD_FOR_S: the page may still draw a pose the car
            # sent before the test's session joined, which the test never heard.
            first_heard = {car.id: published.poses[car.id][0][0] for car in fleet.cars}
            checked_moving = False
            deadline = time.monotonic() + 40
            while time.monotonic() < deadline and not checked_moving:
                published.poll()
                asked = time.time()  # "recently" counts from here: the round trip into a busy page is Playwright's
                drawn = page.eval_on_selector_all("circle.car-body", "cs => cs.map(c => [+c.dataset.car, +c.dataset.x, +c.dataset.y])")
                published.poll()
                if time.time() - max(first_heard.values()) < HEARD_FOR_S:
                    page.wait_for_timeout(100)
                    continue
                for car, x, y in drawn:
                    recent = [(px, py) for t, px, py in published.poses[car] if t > asked - 1.0]
                    assert recent, f"car {car} published no pose lately"
                    gap = min(np.hypot(x - px, y - py) for px, py in recent)
                    assert gap < 0.01, (car, (x, y), recent[-1])
                speeds = [np.hypot(p[-1][1] - p[-5][1], p[-1][2] - p[-5][2]) for p in published.poses.values() if len(p) > 5]
                checked_moving = any(s > 0.05 for s in speeds)  # compared while cars really move
                page.wait_for_timeout(300)
            assert checked_moving, "the cars never moved while the page was watched"
            page.screenshot(path=str(ARTIFACTS / "dashboard-live.png"))
            # Trust: each shown value is one the truster recently published.
            published.poll()
            cells = page.eval_on_selector_all("#trust td[data-trust]:not([data-trust=''])",
                                              "cs => cs.map(c => [+c.dataset.truster, +c.dataset.trustee, +c.dataset.trust])")
            published.poll()
            assert len(cells) == 12
            for a, b, shown in cells:
                said = [v for t, v in published.trust[(a, b)] if t > time.time() - 3.0]
                # On a miss, say how old the shown value is (when the truster said it, if ever).
                ages = [round(time.time() - t, 2) for t, v in published.trust[(a, b)] if abs(shown - v) < 1e-3]
                assert said and min(abs(shown - v) for v in said) < 1e-3, \
                    (a, b, shown, said, f"shown value said {ages or 'never'} s ago")
            # The liar: honest cars' low trust in car 1 raises the alert.
            page.wait_for_selector(".alert[data-kind='low_trust'][data-cars='2,1']", timeout=30000)
            page.click("circle.car-body[data-car='2']")
            page.click("#trust td[data-truster='2'][data-trustee='1']")
            assert "transparency" in page.inner_text("#drill")
            assert page.locator("circle.epsilon").count() == 3
            page.screenshot(path=str(ARTIFACTS / "dashboard-liar.png"))
        finally:
            browser.close()


def test_the_recorded_run_replays_to_the_summary_min_distances(live_run):
    fleet, out, port, published, thread, result = live_run
    thread.join(timeout=180)
    summary = result["summary"]
    view = replay_to_end(out / "run.mcap")
    assert view.distance_source == "ground truth"
    replayed = np.round(view.min_distance, 4)
    assert np.array_equal(replayed, np.array(summary["min_distance"])), (replayed, summary["min_distance"])


def test_the_recording_is_valid_mcap_and_holds_every_message(live_run):
    from mcap.reader import make_reader

    fleet, out, port, published, thread, result = live_run
    thread.join(timeout=180)
    recorded = sum(1 for line in open(out / "messages.jsonl") if '"message"' in line)
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counted = {}
        for schema, channel, message in reader.iter_messages():
            if schema.encoding == "jsonschema":  # the fleet's messages (beside them: Foxglove's scene)
                json.loads(message.data)
            counted[schema.name] = counted.get(schema.name, 0) + 1
    fleet_messages = {k: v for k, v in counted.items() if k.startswith("trustfg.")}
    assert sum(v for k, v in fleet_messages.items() if k != "trustfg.truth") == recorded
    assert counted["trustfg.truth"] > 100
    assert counted["foxglove.SceneUpdate"] > 0 and counted["foxglove.FrameTransforms"] > 0
    assert summary.statistics.message_count == sum(counted.values())
    scenario, events = read_recording(out / "run.mcap")
    assert [c.id for c in scenario.cars] == [1, 2, 3, 4]
    assert all(events[i].at <= events[i + 1].at for i in range(len(events) - 1))


def test_replay_page_has_a_time_slider_that_moves_the_fleet(live_run, tmp_path):
    """The same page, fed by the recording: seeking changes where the cars are drawn."""
    import subprocess
    import sys

    from playwright.sync_api import sync_playwright

    fleet, out, port, published, thread, result = live_run
    thread.join(timeout=180)
    replay_port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "trustfg", "dashboard", "--replay", str(out),
                               "--port", str(replay_port)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        assert wait_for(lambda: page_up(replay_port), 30.0)
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium(), args=CHROMIUM_FLAGS)
            try:
                page = browser.new_page(viewport={"width": 1500, "height": 900})
                page.goto(f"http://127.0.0.1:{replay_port}/")
                page.wait_for_selector("#replay:not([hidden])", timeout=20000)
                page.click("#play")  # pause
                page.eval_on_selector("#slider", "s => { s.value = 1000; s.dispatchEvent(new Event('input')); }")
                page.wait_for_function("document.getElementById('position').textContent.split(' / ')[0] === "
                                       "document.getElementById('position').textContent.split(' / ')[1].replace(' s', '')",
                                       timeout=10000)
                page.wait_for_timeout(400)
                end = page.eval_on_selector_all("circle.car-body", "cs => cs.map(c => [+c.dataset.x, +c.dataset.y])")
                goals = [c.goal for c in fleet.cars]
                assert all(np.hypot(x - gx, y - gy) < 0.15 for (x, y), (gx, gy) in zip(end, goals)), end
                page.screenshot(path=str(ARTIFACTS / "dashboard-replay.png"))
            finally:
                browser.close()
    finally:
        server.terminate()
        server.wait(timeout=10)
        server.stderr.close()


def test_report_renders_figures_and_a_page_from_the_recording(live_run, tmp_path):
    import subprocess
    import sys

    fleet, out, port, published, thread, result = live_run
    thread.join(timeout=180)
    done = subprocess.run([sys.executable, "-m", "trustfg", "report", str(out), "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    page = (tmp_path / "report.html").read_text()
    for name in ("trajectories.png", "min_distance.png", "acceleration.png", "trust.png"):
        assert (tmp_path / name).stat().st_size > 10_000 and name in page
    assert "Minimum distance" in page and "Trust at the end" in page
