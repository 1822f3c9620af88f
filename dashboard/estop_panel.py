"""The dashboard's operator mode (``trustfg dashboard --operator``): an e-stop button, with
release and abort.

The dashboard is then an operator's session (fleet.operator.session): it publishes the
heartbeat the cars' deadman listens for, and ``POST /api/operator`` with ``{"action":
"estop" | "release" | "abort", "cars": [...]}`` (no cars: every car) acts on both stop
paths, as ``trustfg stop`` does. Only the holder of the session's token (random, or from
``--token-file``; printed with the page's address) may press it: the page sends it as
``Authorization: Bearer TOKEN``, and anything else is refused (403) and counted. On a
secure fleet the token must not cross the network in clear text (HTTPS, or a page on
loopback), and the dashboard's Zenoh identity must be the operator's: the cars' access
control drops an e-stop from anyone else (docs/design/links.md, "The dashboard").
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets
from collections import Counter
from pathlib import Path

from ..agent.config import ConfigError, Scenario
from ..fleet.operator.estop_direct import named
from ..fleet.operator.session import OperatorSession

ACTIONS = ("estop", "release", "abort")


def secure_fleet(scenario: Scenario) -> bool:
    """Whether the fleet's bus is secured (TLS endpoints or a Zenoh config with TLS/ACL)."""
    bus = scenario.bus
    endpoints = [*bus.listen, *bus.connect, *(e for car in scenario.cars for e in car.listen)]
    return bool(bus.zenoh_config) or any(e.startswith("tls/") for e in endpoints)


def loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def check_operator_mode(scenario: Scenario, host: str, https: bool) -> None:
    """ConfigError when operator mode would send its token in clear text on a secure fleet."""
    if secure_fleet(scenario) and not https and not loopback(host):
        raise ConfigError("operator mode on a secure fleet needs HTTPS (--tls-cert and --tls-key) "
                          "or a page served on loopback (--host 127.0.0.1)")


def load_token(path: Path | None) -> str:
    """The operator's token: the file's first line, or a fresh random one."""
    if path is None:
        return secrets.token_urlsafe(24)
    try:
        token = path.read_text().strip().splitlines()[0].strip()
    except (OSError, IndexError) as exc:
        raise ConfigError(f"--token-file {path}: cannot read a token ({exc})") from None
    if len(token) < 16:
        raise ConfigError(f"--token-file {path}: a token needs at least 16 characters")
    return token


class OperatorPanel:
    """What the operator's button does, and who may press it."""

    def __init__(self, session: OperatorSession, token: str):
        self.session = session
        self._token = token.encode()
        self.refused: Counter = Counter()

    def authorized(self, authorization: str | None) -> bool:
        presented = (authorization or "").removeprefix("Bearer ").strip().encode()
        return hmac.compare_digest(presented, self._token)

    def act(self, authorization: str | None, body: object) -> tuple[int, dict]:
        """(HTTP status, JSON answer) of one press of a button."""
        if not self.authorized(authorization):
            self.refused["unauthorized"] += 1
            return 403, {"ok": False, "error": "not the operator: the page needs the session's token"}
        if not isinstance(body, dict) or body.get("action") not in ACTIONS:
            self.refused["bad_request"] += 1
            return 400, {"ok": False, "error": f"expected {{\"action\": one of {', '.join(ACTIONS)}, \"cars\": [...]}}"}
        cars = body.get("cars", [])
        try:
            if not isinstance(cars, list) or not all(isinstance(c, int) and not isinstance(c, bool) for c in cars):
                raise ValueError("cars must be a list of car ids")
            named(self.session.fleet, cars)
        except ValueError as exc:
            self.refused["bad_request"] += 1
            return 400, {"ok": False, "error": str(exc)}
        {"estop": self.session.estop, "release": self.session.release, "abort": self.session.abort}[body["action"]](cars)
        return 200, {"ok": True, "did": self.session.log[-1][1]}

    def status(self) -> dict:
        return {"enabled": True, "log": [[round(t, 3), what] for t, what in self.session.log[-5:]],
                "refused": dict(self.refused)}
