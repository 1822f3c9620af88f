"""What a process asks of Zenoh before it opens a session: the zenoh.Config that a
fleet's ``[bus]`` section makes (:func:`zenoh_config`, on top of a lab's own Zenoh file
if it names one), and how many receiving threads Zenoh's runtime starts
(:func:`zenoh_runtime_threads`). Nothing here opens a session: fleet.bus.session does,
and ``trustfg router`` (fleet.bus.router) starts its runtime the same way.
"""

from __future__ import annotations

import json
import logging
import os
import re
from pathlib import Path

import zenoh

from ...agent.config import BusConfig

log = logging.getLogger(__name__)

RX_THREADS = 8
"""Zenoh's receiving threads per process (its default is 2). Zenoh drops a TCP link that
could not flush for a quarter of its lease, and the dropped socket lingers in close() --
SO_LINGER of 10 s, compiled into Zenoh -- inside a receiving thread while unsent data
waits. Under heavy loss two such closes at once leave a process with Zenoh's two threads
hearing nothing from any peer for seconds. A blocked thread sleeps: more of them cost no
CPU, and the others go on receiving. Upstream: eclipse-zenoh/zenoh#1101 (a dropped TCP
link blocks its runtime thread for the linger; Zenoh 1.10 has no setting for it)."""


class BusError(RuntimeError):
    """The Zenoh session could not be opened or configured."""


def zenoh_config(bus: BusConfig, extra_listen: tuple[str, ...] = ()) -> zenoh.Config:
    """A zenoh.Config from our BusConfig, on top of the file ``bus.zenoh_config`` if given.

    The file is the base and ``[bus]`` completes it, never silently overrides it: endpoints
    are added to the file's lists; ``mode``, multicast scouting and its interface and
    ``max_links`` come from the file when it sets them, and a ``[bus]`` value that differs
    both from the file's and from its own default is an error naming both (BusError).
    Zenoh's config answers its own default for a setting a file leaves out, so a file
    value equal to Zenoh's default counts as not set: otherwise a lab's file that does not
    mention ``max_links`` would leave every car one link per peer (Zenoh's 1), no UDP link
    beside the TCP one, and plans queued behind TCP's retransmissions. To ask for Zenoh's
    default value, set it in ``[bus]``."""
    try:
        try:
            config = zenoh.Config.from_file(str(Path(bus.zenoh_config))) if bus.zenoh_config else zenoh.Config()
        except Exception as exc:
            raise BusError(f"bad Zenoh configuration in bus.zenoh_config {bus.zenoh_config}: {_said(exc)}") from exc
        default, zenoh_default = BusConfig(), zenoh.Config()
        for path, field_name in (("mode", "mode"), ("scouting/multicast/enabled", "multicast_scouting"),
                                 ("scouting/multicast/interface", "multicast_interface"),
                                 ("transport/unicast/max_links", "max_links")):
            ours = getattr(bus, field_name)
            theirs = config_value(config, path) if bus.zenoh_config else None
            if theirs is not None and theirs == config_value(zenoh_default, path):
                theirs = None  # not set by the file, or set to what it would be anyway
            if theirs is None:
                if field_name != "multicast_interface" or ours:
                    config.insert_json5(path, json.dumps(ours))
            elif theirs != ours:
                if ours != getattr(default, field_name):
                    raise BusError(f"bus.{field_name} = {ours!r} contradicts {path} = {theirs!r} in "
                                   f"{bus.zenoh_config}: set it in one place")
                log.info("bus.%s: %r from %s", field_name, theirs, bus.zenoh_config)
        if config_value(config, "scouting/multicast/enabled") is False and config_value(config, "scouting/delay") is None:
            # Zenoh waits scouting/delay (500 ms) in open() for peers to scout; with listed
            # endpoints there is nothing to scout (and an e-stop must not wait half a second).
            config.insert_json5("scouting/delay", "0")
        listen = _merged(config_value(config, "listen/endpoints"), [*bus.listen, *extra_listen])
        fixed = [e for e in listen if re.search(r":0(?:$|[?#])", e)]
        if fixed:
            raise BusError(f"listen endpoint {fixed[0]}: port 0 would be a port nobody can be told; name one")
        if listen:
            config.insert_json5("listen/endpoints", json.dumps(listen))
        connect = [e for e in _merged(config_value(config, "connect/endpoints"), list(bus.connect))
                   if e not in listen]  # a fleet-wide list may name us
        if connect:
            config.insert_json5("connect/endpoints", json.dumps(connect))
    except BusError:
        raise
    except Exception as exc:  # zenoh raises ZError and others for bad files or values
        raise BusError(f"bad Zenoh configuration: {_said(exc)}") from exc
    return config


def zenoh_runtime_threads() -> None:
    """Ask for RX_THREADS receiving threads, unless ZENOH_RUNTIME says otherwise. Zenoh
    reads the variable when its runtime starts: call before the process's first session."""
    os.environ.setdefault("ZENOH_RUNTIME", f"(rx: (worker_threads: {RX_THREADS}))")


def _said(exc: Exception) -> str:
    """Zenoh's message on one line, without the Rust source location it ends with."""
    return " ".join(line.strip() for line in str(exc).split(" at /")[0].splitlines() if line.strip())


def config_value(config: zenoh.Config, path: str):
    """A value of a Zenoh config (None when unset)."""
    return json.loads(config.get_json(path))


def _merged(theirs, ours: list[str]) -> list[str]:
    """The file's endpoints, then ours. Per-mode lists (a map) are Zenoh's defaults, which
    ours replace."""
    if isinstance(theirs, dict):
        theirs = []
    merged = []
    for endpoint in [*(theirs or []), *ours]:
        if endpoint not in merged:
            merged.append(endpoint)
    return merged
