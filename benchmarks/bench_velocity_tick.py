"""The command loop's CPU per tick: what the 50 Hz loop of one car costs its process.

    python benchmarks/bench_velocity_tick.py [--cars 8] [--seconds 10] [--runs 3]

One car's control step (fleet.car.velocity_loop: its own pose and the others' from a real
NatNet client, tracking, the proximity guard against the other cars and the walls, the
motion watch, one authenticated command datagram to a real car link) runs at
``control.command_rate_hz`` on absolute deadlines, as in the spawned loop, against
mocap-sim's NatNet server streaming ``--cars`` rigid bodies at 120 Hz: the car drives
north from its start along its plan, the others stand at theirs. Reported per run: the
CPU time of a tick (this thread's, ``time.thread_time``) median / p99, and the share of
one core the loop's ticks take at the command rate. Idle between ticks, as the real loop
is: caches go cold between ticks, so this is dearer than a tight loop of ticks.
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from trustfg.agent.gp import Plan
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.world import build_sdf
from trustfg.bridge import natnet
from trustfg.bridge.carlink import SOURCE_CAR_PROCESS, CommandReceiver, CommandSender, link_key
from trustfg.fleet.car.ticker import ticks
from trustfg.fleet.car.velocity_loop import REPORT_FIELDS, Permit, VelocityLoop, connect_motive
from trustfg.fleet.launch.launcher import default_scenario, loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions

SPEED_MPS = 0.3


def run_once(cars: int, seconds: float, keys: Path) -> tuple[list[float], float]:
    """CPU seconds of every tick of one run, and the command rate."""
    scenario = with_link_keys(loopback_fleet(load_scenario(default_scenario(cars)), cars, None, 0.0), keys)
    car = scenario.cars[0]
    t0 = time.time()
    steps = np.arange(int(seconds / 0.25) + 41) * 0.25
    plan = Plan(t0, 0.25, np.column_stack([np.full(len(steps), car.start[0]), car.start[1] + SPEED_MPS * steps]),
                np.tile([0.0, SPEED_MPS], (len(steps), 1)))

    def bodies(t: float):
        for other in scenario.cars:
            x, y = plan.position_at(np.array([time.time()]))[0] if other is car else other.start
            position, orientation = natnet.from_ground_plane(x, y, math.pi / 2 if other is car else 0.0, 0.05)
            yield other.body_id, f"car{other.id}", position, orientation, True

    options = NatNetServerOptions(address="127.0.0.1", command_port=scenario.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    rate = scenario.control.command_rate_hz
    spent: list[float] = []
    with NatNetServer(options, bodies), CommandReceiver(car.id, (host, int(port)), key=link_key(car)):
        loop = VelocityLoop(scenario, car, [0.0] * len(REPORT_FIELDS), clock=time.time, sdf=build_sdf(scenario.world))
        stop = threading.Event()
        connect_motive(loop, stop)
        loop.plan = plan
        loop.permit = Permit(may_drive=True, trial=1, valid_until=math.inf)
        with CommandSender.for_car(car, source=SOURCE_CAR_PROCESS, stamp_clock=time.time) as sender:
            ended = time.monotonic() + seconds
            for _, now_mono in ticks(1.0 / rate, stop):
                if now_mono >= ended:
                    break
                started = time.thread_time()
                loop.tick(sender, now_mono, 1.0 / rate)
                for answer in sender.answers():
                    loop.answered(answer.e_stop_latched)
                spent.append(time.thread_time() - started)
        loop.natnet.close()
    return spent[int(rate):], rate  # not the first second: caches and the first frames


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cars", type=int, default=8, help="rigid bodies Motive streams (default %(default)s)")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    print(f"command loop, {args.cars} bodies in every frame, {args.seconds:.0f} s per run")
    print(f"{'run':>4} {'ticks':>6} {'tick ms p50':>12} {'p99':>8} {'share of a core':>16}")
    with tempfile.TemporaryDirectory() as folder:
        for run in range(1, args.runs + 1):
            spent, rate = run_once(args.cars, args.seconds, Path(folder) / f"keys-{run}")
            ms = np.array(spent) * 1e3
            share = statistics.fmean(spent) * rate
            print(f"{run:>4} {len(spent):>6} {np.percentile(ms, 50):>12.3f} {np.percentile(ms, 99):>8.3f} "
                  f"{share:>15.1%}", flush=True)


if __name__ == "__main__":
    main()
