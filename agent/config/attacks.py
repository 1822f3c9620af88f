"""How a car may lie, for experiments: the attack suite's names and parameters.

A car with ``attack`` set is a liar (agent.attacks does the lying). In a scenario file::

    [[cars]]
    id = 1
    attack = { name = "bias", params = { bias_m = 0.14, victim = 3 } }

``name`` is one attack or several joined by ``+`` (``"displaced+false-testimony"`` is the
paper's liar: false plans and false testimony); ``params`` sets any parameter of the named
attacks (a parameter two of them share is set for both); the rest keep the defaults
below. On the command line: ``trustfg sim --liar 1 --attack bias --attack-param
bias_m=0.14``. Every parameter is a number (flags: 0 or 1; car ids: 0 means "chosen by
the attack", see each).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from .checks import ConfigError


@dataclass(frozen=True)
class Displaced:
    """The paper's false plans (Sec. IV.C): a fraction ``p`` of plan messages shows the true plan
    moved as a whole by U(offset_min_m, offset_max_m) in a uniformly random direction.
    Other attacks that displace plans take these parameters too."""

    p: float = 0.4
    """Fraction of plan messages that lie, 0 to 1."""
    offset_min_m: float = 0.4
    """Smallest displacement of a false plan."""
    offset_max_m: float = 0.8
    """Largest displacement of a false plan."""


@dataclass(frozen=True)
class ForgedStamp(Displaced):
    """Every plan message is stamped ``shift_s`` off the truth (> 0: in the future, < 0: in
    the past; the plan's own times stay true), and a fraction ``p`` is displaced as in
    ``displaced`` besides."""

    shift_s: float = 0.2
    """How far every plan's stamp is off the truth, s: > 0 in the future, < 0 in the past."""


@dataclass(frozen=True)
class ForgedFuture(ForgedStamp):
    """Every plan message is stamped ``shift_s`` in the future (the plan's own times stay
    true), and a fraction ``p`` is displaced as in ``displaced`` besides."""

    shift_s: float = 0.2
    """How far ahead of the truth every plan's stamp is, s (> 0)."""


@dataclass(frozen=True)
class ForgedPast(ForgedStamp):
    """Every plan message is stamped ``-shift_s`` in the past (the plan's own times stay
    true), and a fraction ``p`` is displaced as in ``displaced`` besides."""

    shift_s: float = -0.2
    """How far off the truth every plan's stamp is, s (< 0: in the past)."""


@dataclass(frozen=True)
class Bias:
    """Every plan is moved ``bias_m`` (below the transparency tolerance, so it reads as
    pose noise) along the line to a victim: ``direction`` 1 claims the car is farther from
    the victim than it is (the harmful side: the victim plans closer), -1 nearer.
    ``victim`` 0: the nearest car seen at each message."""

    bias_m: float = 0.14
    """How far every plan is moved along the line to the victim."""
    victim: float = 0
    """The car the bias aims at; 0: the nearest car seen at each message."""
    direction: float = 1
    """1: the car claims to be farther from the victim than it is; -1: nearer."""


@dataclass(frozen=True)
class FalseFuture:
    """True now, false later: the plan is true at its stamp and bends sideways (``side`` 1:
    left of the direction of travel, -1: right), growing linearly to ``bend_m`` over
    ``ramp_s`` and staying there."""

    bend_m: float = 0.6
    """How far sideways the plan bends at most."""
    ramp_s: float = 1.0
    """Time from the stamp over which the bend grows to bend_m."""
    side: float = 1
    """1: the plan bends left of the direction of travel; -1: right."""


@dataclass(frozen=True)
class FalseYield:
    """Announces that it yields and does not: from its stamp the plan brakes along its true
    path to a stop within ``stop_s`` and waits there, while the car drives on."""

    stop_s: float = 0.5
    """Time from the stamp within which the announced plan comes to a stop."""


@dataclass(frozen=True)
class OnOff(Displaced):
    """Lies in bursts: every plan displaced (``offset_min_m``..``offset_max_m``; ``p`` is not
    used) for ``on_s``, then honest for ``off_s`` (long enough for trust to recover),
    repeating from its first message."""

    on_s: float = 1.0
    """How long each burst of lies lasts."""
    off_s: float = 4.0
    """How long the car is honest between bursts."""


@dataclass(frozen=True)
class Replay:
    """A fraction ``p`` of plan messages replays its own plan of ``age_s`` ago, re-timed as
    if new (fresh stamp and sequence number): it claims to be where it was."""

    p: float = 0.4
    """Fraction of plan messages that replay an old plan, 0 to 1."""
    age_s: float = 1.0
    """How old the replayed plan is."""


@dataclass(frozen=True)
class FalseTestimony:
    """Its trust reports swap success and failure evidence about every peer (it praises
    those it distrusts and slanders those it trusts)."""


@dataclass(frozen=True)
class Slander:
    """Its trust reports claim ``amount`` failures and no success in every dimension about
    ``target`` (0: every peer)."""

    amount: float = 30.0
    """Failures claimed per dimension in each trust report."""
    target: float = 0
    """The slandered car; 0: every peer."""


@dataclass(frozen=True)
class Praise:
    """Its trust reports claim ``amount`` successes and no failure about ``target`` (0:
    every peer)."""

    amount: float = 30.0
    """Successes claimed per dimension in each trust report."""
    target: float = 0
    """The praised car; 0: every peer."""


@dataclass(frozen=True)
class Framing:
    """Tailgates a victim so that the victim looks unsafe, and testifies so: for up to
    ``duration_s`` it drives ``gap_m`` (centre to centre) behind ``victim`` (0: the
    nearest car at its first plan), ignoring the berth it owes it, and reports ``amount``
    safety failures of the victim. Then it drives to its own goal."""

    victim: float = 0
    """The framed car; 0: the nearest car at the framer's first plan."""
    gap_m: float = 0.35
    """Distance, centre to centre, at which it follows the victim."""
    duration_s: float = 10.0
    """How long it tailgates at most before it drives to its own goal."""
    amount: float = 30.0
    """Safety failures of the victim claimed in each trust report."""


@dataclass(frozen=True)
class Collude(Displaced):
    """One of a colluding group (every car whose attack includes ``collude``): it displaces
    a fraction ``p`` of its plans (as ``displaced``), its trust reports claim ``amount``
    successes about every partner and, with ``slander`` 1, swap its evidence about
    everyone else."""

    amount: float = 30.0
    """Successes claimed about every partner in each trust report."""
    slander: float = 1
    """1: its reports also swap its evidence about everyone but its partners; 0: they do not."""


ATTACKS: dict[str, type] = {
    "displaced": Displaced,
    "forged-future": ForgedFuture,
    "forged-past": ForgedPast,
    "bias": Bias,
    "false-future": FalseFuture,
    "false-yield": FalseYield,
    "on-off": OnOff,
    "replay": Replay,
    "false-testimony": FalseTestimony,
    "slander": Slander,
    "praise": Praise,
    "framing": Framing,
    "collude": Collude,
}
"""Every attack by name, with the dataclass of its parameters (defaults, units)."""


@dataclass(frozen=True)
class AttackConfig:
    """A liar's attack: ``name`` (one of ATTACKS, or several joined by ``+``) and the
    parameters that differ from their defaults."""

    name: str
    """The attack: a name of ATTACKS, or several joined by ``+`` (``"displaced+false-testimony"``
    is the paper's liar)."""
    params: dict[str, float] = field(default_factory=dict)
    """Parameters that differ from their defaults, by name (numbers); a parameter two of the
    named attacks share is set for both."""

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.name.split("+"))

    def of(self, name: str):
        """The parameters of attack ``name`` (one of ``names``), defaults filled in."""
        cls = ATTACKS[name]
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in self.params.items() if k in known})

    def validate(self, path: str) -> None:
        for name in self.names:
            if name not in ATTACKS:
                raise ConfigError(f"{path}.name: unknown attack {name!r} (known: {', '.join(ATTACKS)})")
        if len(set(self.names)) != len(self.names):
            raise ConfigError(f"{path}.name: an attack is named twice in {self.name!r}")
        known = {f.name for name in self.names for f in dataclasses.fields(ATTACKS[name])}
        for key, value in self.params.items():
            if key not in known:
                raise ConfigError(f"{path}.params.{key}: not a parameter of {self.name!r} "
                                  f"(it has: {', '.join(sorted(known)) or 'none'})")
            if not math.isfinite(value):
                raise ConfigError(f"{path}.params.{key}: must be finite")
        for name in self.names:
            _check(self.of(name), f"{path}.params")


def _check(params, path: str) -> None:
    """Ranges every attack's parameters must respect."""
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if f.name == "p" and not 0.0 <= value <= 1.0:
            raise ConfigError(f"{path}.p: must be within [0, 1]")
        if f.name in ("victim", "target") and (value != int(value) or not 0 <= value <= 255):
            raise ConfigError(f"{path}.{f.name}: must be a car id (0: chosen by the attack)")
        if f.name in ("direction", "side") and value not in (-1, 1):
            raise ConfigError(f"{path}.{f.name}: must be 1 or -1")
        if f.name.endswith(("_m", "_s")) and f.name != "shift_s" and value < 0:
            raise ConfigError(f"{path}.{f.name}: must be >= 0")
        if f.name in ("stop_s", "ramp_s", "on_s") and value <= 0:
            raise ConfigError(f"{path}.{f.name}: must be > 0")
    if isinstance(params, ForgedFuture) and params.shift_s <= 0:
        raise ConfigError(f"{path}.shift_s: must be > 0 (a stamp in the future)")
    if isinstance(params, ForgedPast) and params.shift_s >= 0:
        raise ConfigError(f"{path}.shift_s: must be < 0 (a stamp in the past)")
    if hasattr(params, "offset_min_m") and params.offset_min_m > params.offset_max_m:
        raise ConfigError(f"{path}: offset_min_m must not exceed offset_max_m")


PAPER_LIAR = "displaced+false-testimony"
"""The paper's liar (Sec. IV.C): false plans and false testimony; what ``--liar`` runs
without ``--attack``."""


def liar_attack(attack: AttackConfig | None, misinformation: float | None) -> AttackConfig:
    """The attack a liar runs: ``attack`` (default: the paper's liar), with
    ``misinformation`` as its fraction ``p`` of false plans when it has one and ``p`` was
    not set otherwise."""
    attack = attack or AttackConfig(PAPER_LIAR)
    takes_p = any(f.name == "p" for name in attack.names for f in dataclasses.fields(ATTACKS[name]))
    if misinformation is not None and takes_p and "p" not in attack.params:
        attack = AttackConfig(attack.name, attack.params | {"p": misinformation})
    attack.validate("attack")
    return attack


def parse_attack(name: str, assignments: list[str] | tuple[str, ...] = ()) -> AttackConfig:
    """``--attack NAME --attack-param k=v ...`` -> a validated AttackConfig."""
    params = {}
    for text in assignments:
        key, sep, value = text.partition("=")
        if not sep or not key:
            raise ConfigError(f"--attack-param {text!r}: expected KEY=NUMBER")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            raise ConfigError(f"--attack-param {text!r}: {value!r} is not a number") from None
    attack = AttackConfig(name, params)
    attack.validate("attack")
    return attack
