"""A car process's trust reports carry the time they go out (fleet.car.process): peers
estimate our clock from these stamps (agent.clocks), and a long replan earlier in the same
pass of the main loop must not age them: on starved cores, stamps taken at the pass's
start would put a car up to half a second behind (the estimate's clamp) on one clock."""

import threading

import pytest

from trustfg.agent import messages
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.car.process import CarProcess
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime

REPLAN_S = 0.8
"""How long each replan takes on the car's clock: a starved machine's."""


def test_a_trust_report_is_stamped_when_it_is_sent_not_when_its_pass_began(intersection, tmp_path):
    fleet = with_link_keys(loopback_fleet(intersection, None, None, 0.0), tmp_path / "keys")
    car = fleet.cars[0]
    now = [100.0]
    process = CarProcess(fleet, car, clock=lambda: now[0])
    replans_ended, reports = [], []  # the clock as each replan ended; (stamp, replans ended before it went out)

    def slow_replan(t: float) -> None:  # a pass's replan: the clock moves on meanwhile
        now[0] += REPLAN_S
        replans_ended.append(now[0])
        if len(replans_ended) >= 6:
            process.stop.set()

    process._replan = slow_replan
    bus = FleetBus(fleet.bus, fleet.fleet, car.id, listen=car.listen, clock=process.clock)
    bus.open()
    sent = bus.publish

    def watched(kind: str, payload: bytes, **how) -> None:  # the real publish, watched
        if kind == "trust":
            reports.append((messages.decode(payload).stamp, list(replans_ended)))
        sent(kind, payload, **how)

    bus.publish = watched
    try:
        loop = threading.Thread(target=process._main_loop, args=(bus,), daemon=True)
        loop.start()
        loop.join(timeout=20.0)
        assert not loop.is_alive()
    finally:
        bus.close()
    assert len(reports) >= 3
    for stamp, ended in reports:  # never older than a replan that ended before it went out
        assert stamp >= max(ended, default=100.0)
