"""``trustfg carlink-test ADDRESS --key FILE``: does a car keep the car link's rules?

Probes a car -- its firmware, the C reference (``firmware/carlink/``) or mocap-sim's
simulated car -- over UDP, one rule of :mod:`.receiver` at a time, and prints one line per
rule, PASS or FAIL with what it measured; exit status 0 only if every rule holds (1 if
one does not, 2 for a usage error or no car answering). The car's state is seen from
outside through its answers to PINGs (:mod:`.answer`): whether an e-stop is latched and
whether the command it applies now is zero. So a probe drives the car (source 0, as a car
process, at ``--speed``), sends what the rule is about (a forged MAC, a replay, an older
session, an e-stop, silence) and asks. Version 2 (authenticated) only.

This module holds the rules, their verdicts (the ``judge_*`` functions, pure) and the
command; what each probe sends and reads, and the socket, are in :mod:`.conformance_probes`.
Run it with the car's wheels off the floor, and with nothing else talking to the car.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .answer import decode_answer
from .conformance_probes import (
    ConformanceOptions,
    Tester,
    UdpProbe,
    Unobservable,
    bad_mac_ignored,
    commands_applied,
    e_stop_any_session,
    e_stop_latched,
    malformed_ignored,
    older_session_refused,
    other_car_ignored,
    ping_answered,
    ping_not_applied,
    replay_ignored,
    restart_taken,
    watchdog_samples,
)
from .frame import SOURCE_OPERATOR, CarLinkError, Flags, command_datagram, new_session
from .keys import parse_key


@dataclass(frozen=True)
class Verdict:
    rule: str
    passed: bool
    figure: str

    def line(self) -> str:
        return f"{'PASS' if self.passed else 'FAIL'}  {self.rule:<40} {self.figure}"


# ------------------------------------------------------------------ verdicts (pure)


def judge_checks(rule: str, checks: list[tuple[str, bool]], noun: str) -> Verdict:
    """All ``checks`` (what, held) must hold; the figure counts them and names the failed."""
    held = sum(ok for _, ok in checks)
    figure = f"{held}/{len(checks)} {noun}"
    failed = [what for what, ok in checks if not ok]
    if failed:
        figure += "; not: " + "; ".join(failed)
    return Verdict(rule, not failed and bool(checks), figure)


def judge_ping(rule: str, round_trips_ms: list[float | None], bound_ms: float) -> Verdict:
    """Every PING answered (authentic, echoing it) and 95 % of them within ``bound_ms``
    (one late answer in 20 may be the tester's own scheduling)."""
    answered = sorted(rt for rt in round_trips_ms if rt is not None)
    n = len(round_trips_ms)
    if not answered:
        return Verdict(rule, False, f"0/{n} answered")
    within = sum(rt <= bound_ms for rt in answered)
    p95 = answered[min(len(answered) - 1, math.ceil(0.95 * len(answered)) - 1)]
    figure = (f"{len(answered)}/{n} answered, {within} within {bound_ms:g} ms: median "
              f"{statistics.median(answered):.2f} ms, 95th percentile {p95:.2f} ms, max {answered[-1]:.2f} ms")
    return Verdict(rule, len(answered) == n and within >= math.ceil(0.95 * n), figure)


def judge_watchdog(rule: str, samples: list[tuple[float, bool]], watchdog_ms: float, slack_ms: float) -> Verdict:
    """``samples``: (ms since the last command was sent, stopped) of the PINGs after it.
    The car must be seen moving first, then stopped, never moving later than the bound."""
    bound = watchdog_ms + slack_ms
    if not samples or samples[0][1]:
        return Verdict(rule, False, "not tested: the command did not drive the car")
    stopped_at = next((age for age, stopped in samples if stopped), None)
    last_moving = max(age for age, stopped in samples if not stopped and (stopped_at is None or age < stopped_at))
    if stopped_at is None:
        return Verdict(rule, False, f"still driving {last_moving:.1f} ms after the last command "
                                    f"(bound {watchdog_ms:g} + {slack_ms:g} ms)")
    return Verdict(rule, last_moving <= bound,
                   f"stopped {last_moving:.1f}-{stopped_at:.1f} ms after the last command "
                   f"(bound {watchdog_ms:g} + {slack_ms:g} ms)")


# ------------------------------------------------------------------------ the run


@dataclass(frozen=True)
class Rule:
    name: str
    run: Callable[[Tester], Verdict]


def rules(options: ConformanceOptions) -> list[Rule]:
    """The rules in the order they run; the first, PING, is what every other probe sees by."""
    bound, wd, slack = options.ping_bound_ms, options.watchdog_ms, options.watchdog_slack_ms

    def checked(name: str, probe: Callable[[Tester], list[tuple[str, bool]]], noun: str) -> Rule:
        return Rule(name, lambda t: judge_checks(name, probe(t), noun))

    ping_rule = f"PING answered within {bound:g} ms"
    watchdog_rule = f"watchdog stops within {wd:g} ms"
    return [
        Rule(ping_rule, lambda t: judge_ping(ping_rule, ping_answered(t), bound)),
        checked("commands applied, STOP not latched", commands_applied, "held"),
        checked("restarted sender's new session taken", restart_taken, "held"),
        checked("bad MAC ignored", bad_mac_ignored, "forged datagrams ignored"),
        checked("replay ignored", replay_ignored, "replays ignored"),
        checked("older session refused after a restart", older_session_refused, "refused"),
        Rule(watchdog_rule, lambda t: judge_watchdog(watchdog_rule, watchdog_samples(t), wd, slack)),
        checked("E_STOP latched until its RELEASE", e_stop_latched, "held"),
        checked("E_STOP taken from any session or seq", e_stop_any_session, "latched"),
        checked("PING never applied", ping_not_applied, "held"),
        checked("other car's datagrams ignored", other_car_ignored, "ignored"),
        checked("malformed datagrams ignored", malformed_ignored, "ignored"),
    ]


def run(probe: UdpProbe, options: ConformanceOptions,
        report: Callable[[Verdict], None] = lambda verdict: None) -> list[Verdict]:
    """Every rule against the car behind ``probe``, each from a released, standing car;
    ``report`` sees each verdict as it is made. The car is left released and standing."""
    tester = Tester(probe, options)
    verdicts: list[Verdict] = []
    for rule in rules(options):
        if verdicts and not tester.answers:
            verdict = Verdict(rule.name, False, "not tested: the car answers no PING, its state cannot be seen")
        else:
            try:
                if verdicts:
                    tester.reset()
                verdict = rule.run(tester)
            except Unobservable as exc:
                verdict = Verdict(rule.name, False, f"not tested: {exc}")
        verdicts.append(verdict)
        report(verdict)
    try:
        tester.reset()
    except Unobservable:
        pass
    return verdicts


def find_cars(probe: UdpProbe, key: bytes, wait_s: float = 0.3) -> list[int]:
    """The car ids that answer a PING (one to each id, 1..255) at the probe's address."""
    session = new_session()
    for car_id in range(1, 256):
        probe.send(command_datagram(key, car_id, car_id, time.time(), 0.0, 0.0, Flags.PING, session,
                                    SOURCE_OPERATOR))
    found, until = set(), time.monotonic() + wait_s
    while (got := probe.receive(until)) is not None:
        try:
            answer = decode_answer(got[0], key)
        except CarLinkError:
            continue
        if answer.session == session and answer.seq == answer.car_id:
            found.add(answer.car_id)
    return sorted(found)


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` or ``udp://HOST:PORT`` (a car's ``link`` in a fleet config)."""
    host, _, port = text.removeprefix("udp://").rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"expected HOST:PORT or udp://HOST:PORT, got {text!r}")
    return host.strip("[]"), int(port)


DESCRIPTION = """\
Probe a car's link over UDP, rule by rule of the receiver (bridge/carlink/receiver.py), and
print one line per rule: PASS or FAIL with what was measured. Exit status 0 only if every
rule holds, 1 if one does not, 2 for a usage error or no car answering.

The car's state is read from its answers to PINGs (e-stop latched; stopped). The probes
drive the car at --speed for moments: run it with the wheels off the floor, and with
nothing else talking to the car (no car process, no operator's tools)."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, as every trustfg command
        self.exit(2, f"{self.prog}: {message} (see --help)\n")


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(prog="trustfg carlink-test", allow_abbrev=False, description=DESCRIPTION,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    defaults = ConformanceOptions(1, bytes(32))
    parser.add_argument("address", help="the car's link: HOST:PORT or udp://HOST:PORT")
    parser.add_argument("--key", required=True, type=Path, metavar="FILE", help="the car's key file (64 hex digits)")
    parser.add_argument("--car", type=int, default=None, metavar="ID",
                        help="the car's id (default: whichever answers a PING)")
    parser.add_argument("--speed", type=float, default=defaults.speed_mps, metavar="MPS",
                        help="the probes' speed, m/s (default: %(default)s)")
    parser.add_argument("--pings", type=int, default=defaults.pings, metavar="N",
                        help="PINGs timed (default: %(default)s)")
    parser.add_argument("--ping-bound-ms", type=float, default=defaults.ping_bound_ms, metavar="MS",
                        help="a PING's answer within this, ms (default: %(default)s)")
    parser.add_argument("--watchdog-ms", type=float, default=defaults.watchdog_ms, metavar="MS",
                        help="the watchdog's stop within this, ms (default: %(default)s)")
    parser.add_argument("--watchdog-slack-ms", type=float, default=defaults.watchdog_slack_ms, metavar="MS",
                        help="allowed beyond it for the link's delay and sampling, ms (default: %(default)s)")
    args = parser.parse_args(argv)
    prog = parser.prog
    try:
        address = parse_address(args.address)
        key = parse_key(args.key.read_text(), f"--key {args.key}")
    except OSError as exc:
        print(f"{prog}: cannot read the key file {args.key}: {exc.strerror}", file=sys.stderr)
        return 2
    except ValueError as exc:  # a bad address, or a ConfigError for the key
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    if args.car is not None and not 1 <= args.car <= 255:
        parser.error("--car takes 1..255")
    if not (args.pings > 0 and args.speed > 0 and args.ping_bound_ms > 0 and args.watchdog_ms > 0):
        parser.error("--pings, --speed, --ping-bound-ms and --watchdog-ms must be > 0")
    try:
        with UdpProbe(address) as probe:
            cars = [args.car] if args.car is not None else find_cars(probe, key)
            if len(cars) != 1:
                print(f"{prog}: {'no car' if not cars else f'cars {cars}'} answered a PING at {args.address} "
                      f"with this key (name one with --car, or check the address, the key and that the car runs)",
                      file=sys.stderr)
                return 2
            options = ConformanceOptions(cars[0], key, speed_mps=args.speed, pings=args.pings,
                                         ping_bound_ms=args.ping_bound_ms, watchdog_ms=args.watchdog_ms,
                                         watchdog_slack_ms=args.watchdog_slack_ms)
            print(f"car {options.car_id} at {address[0]}:{address[1]}, car link version 2", flush=True)
            verdicts = run(probe, options, lambda verdict: print(verdict.line(), flush=True))
    except OSError as exc:  # an unknown host, no route
        print(f"{prog}: {args.address}: {exc}", file=sys.stderr)
        return 2
    held = sum(v.passed for v in verdicts)
    print(f"{held} of {len(verdicts)} rules hold")
    return 0 if held == len(verdicts) else 1
