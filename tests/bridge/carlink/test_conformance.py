"""``trustfg carlink-test``: its verdicts on their own, then the whole test against cars
that keep the rules (the Python receiver thread, mocap-sim's simulated cars, the C
reference's POSIX car) and against variants of the C reference each broken in one rule,
which the matching line -- and only it -- must catch."""

from __future__ import annotations

import contextlib
import dataclasses
import re
import subprocess
import sys
import time

import pytest

from tests.firmware.carlink_reference import build_posix, posix_car, variant
from trustfg.agent.scenario_files import dump_scenario
from trustfg.bridge.carlink import CommandReceiver, new_key, write_key_file
from trustfg.bridge.carlink.conformance import (
    ConformanceOptions,
    judge_checks,
    judge_ping,
    judge_watchdog,
    main,
    rules,
)
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime

CAR = 3
RULES = [rule.name for rule in rules(ConformanceOptions(CAR, bytes(32)))]
PING, WATCHDOG = RULES[0], RULES[6]


# ----------------------------------------------------------------- verdicts (pure)


def test_the_ping_verdict_wants_every_answer_and_95_percent_in_time():
    assert judge_ping(PING, [0.1] * 20, 10.0).passed
    assert judge_ping(PING, [0.1] * 19 + [12.0], 10.0).passed  # one late in 20: the tester's scheduling
    late = judge_ping(PING, [0.1] * 18 + [12.0, 30.0], 10.0)
    assert not late.passed and "18 within 10 ms" in late.figure and "max 30.00 ms" in late.figure
    lost = judge_ping(PING, [0.1] * 19 + [None], 10.0)
    assert not lost.passed and lost.figure.startswith("19/20 answered")
    assert judge_ping(PING, [None] * 20, 10.0).figure == "0/20 answered"


def test_the_watchdog_verdict_reads_when_the_car_stopped():
    moving_then_stopped = [(1.0, False), (120.0, False), (249.0, False), (251.5, True)]
    verdict = judge_watchdog(WATCHDOG, moving_then_stopped, 250.0, 25.0)
    assert verdict.passed and verdict.figure.startswith("stopped 249.0-251.5 ms after the last command")
    assert not judge_watchdog(WATCHDOG, [(1.0, False), (280.0, False), (282.0, True)], 250.0, 25.0).passed
    never = judge_watchdog(WATCHDOG, [(1.0, False), (999.0, False)], 250.0, 25.0)
    assert not never.passed and never.figure.startswith("still driving 999.0 ms")
    assert judge_watchdog(WATCHDOG, [(1.0, True)], 250.0, 25.0).figure.startswith("not tested")


def test_a_checked_rule_holds_only_if_every_check_does_and_names_those_that_did_not():
    held = judge_checks("r", [("a", True), ("b", True)], "ignored")
    assert held.passed and held.figure == "2/2 ignored"
    failed = judge_checks("r", [("a", True), ("b", False), ("c", False)], "ignored")
    assert not failed.passed and failed.figure == "1/3 ignored; not: b; c"
    assert failed.line().startswith("FAIL  r ")


# ------------------------------------------------------------ whole runs against cars


def verdicts_of(output: str) -> dict[str, tuple[bool, str]]:
    """Rule -> (passed, figure) from the command's output, which has a line for every rule."""
    found = {}
    for line in output.splitlines():
        if line[:4] in ("PASS", "FAIL"):
            found[line[6:46].strip()] = (line[:4] == "PASS", line[46:].strip())
    assert list(found) == RULES, output
    return found


def failed(output: str) -> set[str]:
    return {rule for rule, (passed, _) in verdicts_of(output).items() if not passed}


@pytest.fixture
def key_file(tmp_path):
    key = new_key()
    return key, write_key_file(tmp_path / "car.key", key)


def test_a_car_running_the_python_receiver_passes(key_file, capsys):
    key, path = key_file
    with CommandReceiver(CAR, ("127.0.0.1", 0), key=key) as car:
        started = time.monotonic()
        code = main([f"{car.address[0]}:{car.address[1]}", "--key", str(path), "--car", str(CAR)])
        took = time.monotonic() - started
        counts = car.counters
    output = capsys.readouterr().out
    assert code == 0, output
    assert failed(output) == set() and output.rstrip().endswith("12 of 12 rules hold")
    assert took < 10.0
    # the probes reached the car: forgeries, replays, old sessions, malformed datagrams
    assert counts.decode_errors["mac"] >= 4 and counts.repeated_seq >= 1 and counts.stale_seq >= 1
    assert counts.old_session >= 3 and counts.wrong_car >= 2 and counts.e_stops >= 4
    assert {"reserved", "flags", "car_id", "magic", "version", "length", "non_finite"} <= set(counts.decode_errors)


def test_mocap_sims_simulated_cars_pass_found_by_their_answers(intersection, tmp_path):
    fleet = with_link_keys(loopback_fleet(dataclasses.replace(intersection, cars=intersection.cars[:2]), None),
                           tmp_path / "keys")
    config = tmp_path / "fleet.toml"
    config.write_text(dump_scenario(fleet))
    mocap = subprocess.Popen([sys.executable, "-m", "trustfg", "mocap-sim", "--config", str(config)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ports = mocap.stdout.readline()
        assert mocap.stdout.readline().strip() == "READY", ports + mocap.stderr.read()
        car = fleet.cars[1]
        assert f"{car.id}={car.link}" in ports
        done = subprocess.run([sys.executable, "-m", "trustfg", "carlink-test", car.link, "--key",
                               car.link_key_file], capture_output=True, text=True, timeout=30)
    finally:
        mocap.terminate()
        try:
            assert mocap.wait(timeout=5) == 0
        finally:
            if mocap.poll() is None:
                mocap.kill()
                mocap.wait()
            mocap.stdout.close()
            mocap.stderr.close()
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith(f"car {car.id} at 127.0.0.1:")  # found by a PING to every id
    assert failed(done.stdout) == set()


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return build_posix(tmp_path_factory.mktemp("reference") / "carlink_posix")


def test_the_c_reference_passes(reference, key_file):
    _, path = key_file
    with posix_car(reference, CAR, path) as (address, output):
        done = subprocess.run([sys.executable, "-m", "trustfg", "carlink-test", f"udp://{address[0]}:{address[1]}",
                               "--key", str(path)], capture_output=True, text=True, timeout=30)
    assert done.returncode == 0, done.stdout + done.stderr
    print(done.stdout)  # the conformance report of the reference (pytest -s shows it)
    verdicts = verdicts_of(done.stdout)
    assert failed(done.stdout) == set()
    ping_figure = verdicts[PING][1]
    assert re.match(r"20/20 answered, 20 within 10 ms: median \d+\.\d\d ms", ping_figure)
    low, high = map(float, re.match(r"stopped (\S+)-(\S+) ms", verdicts[WATCHDOG][1]).groups())
    assert 200.0 < low < high <= 275.0
    assert "e-stop latched by source 1" in "".join(output) and output[-1].startswith("carlink: accepted ")


BROKEN = {
    "the MAC not checked": (
        [("carlink.c", "if (differ(mac, d + 36, CARLINK_MAC_BYTES))", "if (differ(mac, d + 36, CARLINK_MAC_BYTES) && 0)")],
        {"bad MAC ignored"}),
    "replays taken": (
        [("carlink.c", "if (c->seq <= s->session_seq[src]) {", "if (c->seq <= s->session_seq[src] && 0) {")],
        {"replay ignored"}),
    "an older session taken as a restart": (
        [("carlink.c", "|| c->session > s->session[src]) {", "|| c->session != s->session[src]) {")],
        {"older session refused after a restart"}),
    "no watchdog": (
        [("carlink.c", "&& (uint32_t)(now_ms - s->last_ms) < s->watchdog_ms)",
          "&& ((uint32_t)(now_ms - s->last_ms) < s->watchdog_ms || 1))")],
        {WATCHDOG}),
    "E_STOP not latched: its source's next command releases it": (
        [("carlink.c", "if ((c->flags & CARLINK_RELEASE) && bit(s->e_stop, c->source))",
          "if (bit(s->e_stop, c->source))")],
        {"E_STOP latched until its RELEASE"}),
    "PING answered 20 ms late": (
        [("carlink_posix.c", "if (result.answer_len > 0\n",
          "if (result.answer_len > 0 && nanosleep(&(struct timespec){0, 20000000L}, NULL) == 0\n")],
        {PING}),
    "PING not answered": (
        [("carlink_posix.c", "if (result.answer_len > 0\n", "if (result.answer_len > 9999\n")],
        set(RULES)),
}


@pytest.mark.parametrize("broken", list(BROKEN))
def test_a_c_reference_broken_in_one_rule_fails_that_rule_alone(broken, tmp_path, key_file, capsys):
    substitutions, expected = BROKEN[broken]
    binary = build_posix(tmp_path / "carlink_posix", variant(tmp_path / "src", substitutions))
    _, path = key_file
    with posix_car(binary, CAR, path) as (address, _):
        code = main([f"{address[0]}:{address[1]}", "--key", str(path), "--car", str(CAR)])
    output = capsys.readouterr().out
    assert code == 1
    assert failed(output) == expected, output
    verdicts = verdicts_of(output)
    if broken == "PING not answered":
        assert verdicts[PING][1] == "0/20 answered"
        assert all(figure.startswith("not tested: the car answers no PING") for rule, (_, figure) in verdicts.items()
                   if rule != PING)
    elif broken == "PING answered 20 ms late":
        median = re.match(r"20/20 answered, 0 within 10 ms: median (\S+) ms", verdicts[PING][1])
        assert median and float(median.group(1)) >= 20.0
    elif broken == "no watchdog":
        assert verdicts[WATCHDOG][1].startswith("still driving")
    else:
        assert "; not: " in verdicts[next(iter(expected))][1]


def test_no_car_at_the_address_is_an_error_of_one_line(key_file, capsys):
    _, path = key_file
    with CommandReceiver(CAR, ("127.0.0.1", 0), key=new_key()) as other_keys_car:  # answers nobody with our key
        address = f"{other_keys_car.address[0]}:{other_keys_car.address[1]}"
        assert main([address, "--key", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no car answered a PING" in err


@pytest.mark.parametrize("argv, message", [
    (["127.0.0.1:9", "--key", "no-such-file"], "cannot read the key file"),
    (["127.0.0.1", "--key", "KEY"], "expected HOST:PORT"),
    (["127.0.0.1:9", "--key", "KEY", "--car", "0"], "--car takes 1..255"),
])
def test_user_errors_are_one_line(argv, message, key_file, capsys):
    argv = [str(key_file[1]) if a == "KEY" else a for a in argv]
    with pytest.raises(SystemExit) if "--car" in argv else contextlib.nullcontext():  # argparse's exit
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_the_command_is_registered():
    done = subprocess.run([sys.executable, "-m", "trustfg", "--help"], capture_output=True, text=True, timeout=30)
    assert "carlink-test" in done.stdout
