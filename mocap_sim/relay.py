"""Real cars among simulated ones: mocap-sim relays a real motion capture's rigid bodies.

A mixed fleet marks its real cars ``simulated = false``. With ``--relay LAB.toml``
mocap-sim reads the motion capture that file's ``[natnet]`` names (Motive) with the
bridge's NatNet client, set up as a car process sets up its own, and serves one merged
stream, of the NatNet version the upstream streams (:func:`served_version`). Merged frames
are mocap-sim's own (its frame numbers, timestamps, clock and rate);
each carries its simulated cars and the newest upstream sample of every real car seen so
far, with the pose, mean error and tracking-valid flag the upstream gave. A sample older
than ``stale_s`` when a frame is made (the upstream went quiet) is served untracked, as
any untracked body, never with a pose the relay made up: a car process takes no pose from
an untracked body, so it stops that car at once. :func:`check_relay` refuses configs
whose streams a car process could confuse; at start :class:`Relay` refuses a simulated
car whose rigid body the upstream streams too.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass, replace
from typing import Iterable, Iterator, Mapping

from ..agent.config import ConfigError, NatNetConfig, Scenario
from ..bridge import natnet
from ..bridge.natnet import Version
from ..bridge.natnet_client import BodySample, NatNetClient, NatNetConnectionError, client_options
from .natnet_server import BodySource, ServedBody

__all__ = ["RelayOptions", "Relay", "check_relay", "merge", "relayed", "served_version"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RelayOptions:
    """Where a mixed fleet's real cars are tracked, and how long a sample of them stays fresh."""

    upstream: NatNetConfig
    """The real motion capture, as the lab's config names it in ``[natnet]``."""
    stale_s: float = 0.05
    """An upstream sample older than this when a merged frame is made is served untracked,
    in s (6 frames of Motive at 120 Hz): a real car's pose is never older than this when
    its frame leaves, so its car process's pose timeout holds within this much."""
    first_frame_timeout_s: float = 5.0
    """How long the start waits for the upstream's first frame, whose rigid bodies are
    checked against the simulated cars', in s."""

    def __post_init__(self) -> None:
        for name in ("stale_s", "first_frame_timeout_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"relay {name}: must be > 0, got {value}")


def check_relay(scenario: Scenario, relay: RelayOptions | None) -> None:
    """ConfigError for a mixed fleet mocap-sim cannot serve: real cars and no upstream, an
    upstream and no real car, an upstream that is the merged stream itself, both streams
    multicast to one group and port (car processes would take frames of both), or up axes
    that differ (the real poses pass unchanged)."""
    real = [car.id for car in scenario.cars if not car.simulated]
    if relay is None:
        if real:
            raise ConfigError(f"cars {real} are real (simulated = false): mocap-sim relays them only with "
                              "--relay LAB.toml, the config whose [natnet] names the real motion capture")
        return
    if not real:
        raise ConfigError("--relay: no car of the config is real (simulated = false), so there is nothing to relay")
    up, merged = relay.upstream, scenario.natnet
    if (up.server, up.command_port) == (merged.server, merged.command_port):
        raise ConfigError(f"--relay: the upstream at {up.server}:{up.command_port} is this config's own [natnet] "
                          "server and command_port, where the merged stream is served: give one of them another")
    if up.mode == merged.mode == "multicast" and (up.multicast_group, up.data_port) == (
            merged.multicast_group, merged.data_port):
        raise ConfigError(f"natnet: the merged stream and the upstream both multicast to {up.multicast_group}:"
                          f"{up.data_port}, and car processes would take frames of both: give [natnet] another "
                          "multicast_group or data_port, or mode = \"unicast\"")
    if up.up_axis != merged.up_axis:
        raise ConfigError(f"natnet.up_axis: {merged.up_axis!r} here but {up.up_axis!r} upstream: the real cars' "
                          "poses pass unchanged, so both configs need Motive's up axis")


def merge(simulated: Iterable[ServedBody], upstream: Mapping[int, BodySample], real: Mapping[int, str],
          now: float, stale_s: float) -> list[ServedBody]:
    """One merged frame's bodies: the simulated ones, then, for each real rigid body of
    ``real`` (id -> name) the upstream has streamed, its newest sample as it came (with its
    mean error, which tells the server to add no noise), untracked once older than
    ``stale_s``. ``now`` and the samples' ``received_s`` are on one clock (monotonic)."""
    bodies = list(simulated)
    for body_id, name in real.items():
        sample = upstream.get(body_id)
        if sample is None:
            continue
        body = sample.body
        fresh = now - sample.received_s <= stale_s
        bodies.append((body_id, name, body.position, body.orientation, body.tracking_valid and fresh,
                       body.mean_error))
    return bodies


def served_version(upstream: Version) -> Version:
    """The NatNet version the merged stream speaks for an upstream of ``upstream``: the same
    where mocap-sim encodes it; 4.2, whose layout they keep, for 4.3 and later; the default
    for a 2.x upstream, which it encodes no longer."""
    for version in natnet.FRAME_VERSIONS:
        if (version.major, version.minor) == (upstream.major, upstream.minor):
            return version
    if (upstream.major, upstream.minor) > (natnet.NEWEST_LAYOUT.major, natnet.NEWEST_LAYOUT.minor):
        return natnet.NEWEST_LAYOUT
    return natnet.DEFAULT_VERSION


class Relay:
    """The upstream's NatNet client (pulled by the merged stream's thread: no thread of its
    own) and the merge; a context manager whose start checks the upstream (module docstring).
    ``client`` replaces the one made from ``options`` (tests)."""

    def __init__(self, options: RelayOptions, scenario: Scenario, client: NatNetClient | None = None) -> None:
        self.options = options
        self.real = {car.body_id: car.id for car in scenario.cars if not car.simulated}
        """Real cars: rigid-body id -> car id."""
        self.simulated = {car.body_id: car.id for car in scenario.cars if car.simulated}
        """Simulated cars: rigid-body id -> car id."""
        self._client = client or NatNetClient(replace(client_options(options.upstream),
                                                      client_name="trustfg mocap-sim relay", pull=True))
        self._clashing: frozenset[int] = frozenset()

    @property
    def upstream_version(self) -> Version | None:
        """The NatNet version the upstream streams (None before the start)."""
        return self._client.version

    @property
    def upstream_address(self) -> str:
        return f"{self.options.upstream.server}:{self.options.upstream.command_port}"

    def __enter__(self) -> "Relay":
        self._client.start()  # NatNetConnectionError when the upstream does not answer
        try:
            self._check_upstream()
        except BaseException:
            self._client.close()
            raise
        log.info("relay: cars %s from the NatNet server at %s", sorted(self.real.values()), self.upstream_address)
        return self

    def __exit__(self, *exc_info: object) -> None:
        stats = self._client.stats()
        log.info("relay: %d upstream frames taken, %d lost on the way", stats.decoded, stats.dropped)
        self._client.close()

    def _check_upstream(self) -> None:
        """The upstream streams, and none of its rigid bodies is a simulated car's."""
        if not self._client.wait_for_frames(1, self.options.first_frame_timeout_s):
            raise NatNetConnectionError(f"the NatNet server at {self.upstream_address} answered but sent no frame "
                                        f"in {self.options.first_frame_timeout_s:.0f} s (is it streaming?)")
        streamed = set(self._client.latest_all()) | set(self._client.body_ids().values())
        clash = sorted(streamed & set(self.simulated))
        if clash:
            cars = [self.simulated[body] for body in clash]
            raise ConfigError(f"cars {cars} are simulated, but their rigid bodies {clash} are also in the stream "
                              f"of the NatNet server at {self.upstream_address}: give them other rigid_body ids, "
                              "or mark them simulated = false if they are the real ones")
        unseen = sorted(car for body, car in self.real.items() if body not in streamed)
        if unseen:
            log.warning("relay: real cars %s are not in the upstream stream yet (relayed once they are)", unseen)

    def source(self, simulated: BodySource) -> BodySource:
        """The merged stream's pose source: ``simulated``'s bodies and the real cars'."""
        def bodies(t: float) -> list[ServedBody]:
            upstream = self._client.latest_all()
            self._watch(upstream)
            names = {body: name for name, body in self._client.body_ids().items()}
            real = {body: names.get(body, f"car{car}") for body, car in self.real.items()}
            return merge(simulated(t), upstream, real, time.monotonic(), self.options.stale_s)
        return bodies

    def _watch(self, upstream: Mapping[int, BodySample]) -> None:
        """Log once when the upstream starts streaming a simulated car's rigid body (that
        body of the upstream is never relayed: only the real cars' are)."""
        clashing = frozenset(upstream) & frozenset(self.simulated)
        if clashing - self._clashing:
            log.error("relay: the upstream now streams rigid bodies %s, which are simulated cars' here; "
                      "the simulated ones are served", sorted(clashing - self._clashing))
        self._clashing = clashing


@contextlib.contextmanager
def relayed(scenario: Scenario, relay: RelayOptions | None,
            simulated: BodySource) -> Iterator[tuple[BodySource, Version | None]]:
    """mocap-sim's pose source and the upstream's NatNet version: ``simulated`` and None
    without a relay; with one, the merged source while the relay runs."""
    if relay is None:
        yield simulated, None
        return
    with Relay(relay, scenario) as running:
        yield running.source(simulated), running.upstream_version
