"""The Zenoh configuration a fleet's [bus] makes, and Zenoh's receiving threads, on real
Zenoh sessions over loopback TCP, multicast scouting off."""

import json
import socket
from pathlib import Path

import pytest

import trustfg
from tests.conftest import wait_for
from trustfg.agent.config import BusConfig
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.bus.zenoh_setup import RX_THREADS, BusError, zenoh_config
from trustfg.fleet.launch.ports import free_port

pytestmark = pytest.mark.realtime

FLEET = "t"


def endpoint():
    return f"tcp/127.0.0.1:{free_port()}"


def udp_endpoint():
    return f"udp/127.0.0.1:{free_port(socket.SOCK_DGRAM)}?rel=0"


def test_bad_zenoh_settings_are_a_clear_error(tmp_path):
    bad = tmp_path / "bad.json5"
    bad.write_text("{ this is not json5 ")
    with pytest.raises(BusError, match="bad Zenoh configuration"):
        FleetBus(BusConfig(zenoh_config=str(bad)), FLEET, 1).open()


def test_a_zenoh_config_file_is_completed_by_bus_values_and_a_contradiction_is_an_error(tmp_path):
    base = tmp_path / "base.json5"
    base.write_text('{ mode: "client", connect: { endpoints: ["tcp/10.0.0.2:7447"] } }')
    config = zenoh_config(BusConfig(connect=("tcp/10.0.0.3:7447",), zenoh_config=str(base)), ("tcp/127.0.0.1:7450",))
    assert json.loads(config.get_json("mode")) == "client"  # [bus] left mode at its default: the file's
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/10.0.0.2:7447", "tcp/10.0.0.3:7447"]
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7450"]
    with pytest.raises(BusError, match="bus.multicast_scouting = True contradicts"):
        base.write_text('{ scouting: { multicast: { enabled: false } } }')
        zenoh_config(BusConfig(multicast_scouting=True, zenoh_config=str(base)))
    without_file = zenoh_config(BusConfig(mode="client"))
    assert json.loads(without_file.get_json("mode")) == "client"


def test_a_setting_the_file_leaves_out_is_ours_not_zenohs_default(tmp_path):
    """Zenoh answers its own default (max_links 1) for a setting a file does not name: the
    file must not be taken to have set it, or a lab's file quietly leaves each car one
    link per peer and no UDP link for the plans. What the file does set, it sets."""
    base = tmp_path / "base.json5"
    base.write_text('{ mode: "peer", scouting: { multicast: { enabled: false } } }')
    config = zenoh_config(BusConfig(zenoh_config=str(base)))
    assert json.loads(config.get_json("transport/unicast/max_links")) == BusConfig().max_links
    assert json.loads(zenoh_config(BusConfig(zenoh_config=str(base), max_links=1))
                      .get_json("transport/unicast/max_links")) == 1
    base.write_text('{ transport: { unicast: { max_links: 2 } } }')
    assert json.loads(zenoh_config(BusConfig(zenoh_config=str(base))).get_json("transport/unicast/max_links")) == 2
    with pytest.raises(BusError, match="bus.max_links = 3 contradicts"):
        zenoh_config(BusConfig(zenoh_config=str(base), max_links=3))


def test_the_labs_zenoh_file_leaves_room_for_the_udp_link():
    """deploy/zenoh/peer-endpoints.json5 does not name max_links, and Zenoh answers its
    own default (one link per peer) for it: taken as the file's word, that would leave the
    peers their TCP link only and no UDP one for the best-effort plans."""
    base = str(Path(trustfg.__file__).parent / "deploy" / "zenoh" / "peer-endpoints.json5")
    a, a_udp = endpoint(), udp_endpoint()
    with FleetBus(BusConfig(listen=(a, a_udp), zenoh_config=base), FLEET, 1), \
            FleetBus(BusConfig(listen=(endpoint(), udp_endpoint()), connect=(a, a_udp), zenoh_config=base),
                     FLEET, 2) as two:
        assert wait_for(lambda: {reliable for *_, reliable in two.links()} == {True, False}, 5.0), two.links()
        assert any(src.startswith("udp/") and not reliable for src, _, reliable in two.links())


def test_a_listen_endpoint_on_port_0_is_refused():
    with pytest.raises(BusError, match="port 0"):
        zenoh_config(BusConfig(listen=("tcp/127.0.0.1:0",)))


RX_THREADS_PROBE = """
import os, time
from trustfg.agent.config import BusConfig
from trustfg.fleet.bus.session import FleetBus
a, b = "tcp/127.0.0.1:{a}", "tcp/127.0.0.1:{b}"
with FleetBus(BusConfig(listen=(a,)), "t", 1) as one, FleetBus(BusConfig(listen=(b,), connect=(a,)), "t", 2) as two:
    deadline = time.monotonic() + 10
    while not (one.alive.get(2) and two.alive.get(1)) and time.monotonic() < deadline:
        time.sleep(0.05)
    names = [open(f"/proc/self/task/{{t}}/comm").read().strip() for t in os.listdir("/proc/self/task")]
    print(sum(name.startswith("rx-") for name in names))
"""


@pytest.mark.parametrize("preset, threads", [(None, None), ("(rx: (worker_threads: 3))", 3)])
def test_zenoh_receives_on_as_many_threads_as_the_bus_asks_unless_told_otherwise(preset, threads):
    """Zenoh's lingering TCP closes block a receiving thread each (RX_THREADS): a car
    process asks for more of them than Zenoh's two; a ZENOH_RUNTIME of the user's stands."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
    if preset is not None:
        env["ZENOH_RUNTIME"] = preset
    probe = RX_THREADS_PROBE.format(a=free_port(), b=free_port())
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout.strip().splitlines()[-1]) == (threads or RX_THREADS)
