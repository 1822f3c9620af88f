"""``trustfg keys``: every car's link key and TLS files with their modes, made once (a second
run, and adding a car, leave every existing file as it was), replaced only when told, and
never given to the wrong owner; openssl makes the certificates, as on a lab's laptop."""

import os
import pwd
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.conftest import ROOT
from trustfg.agent.scenario_files import load_scenario
from trustfg.bridge.carlink.keys import parse_key
from trustfg.fleet.bus import certificates
from trustfg.fleet.bus.security import secure_config
from trustfg.fleet.operator.keys import KeysError, owner_of, survey

pytestmark = pytest.mark.realtime

ME = pwd.getpwuid(os.geteuid()).pw_name


def lab_guide_car_5() -> str:
    """The ``[[cars]]`` entry docs/lab-guide.md adds, as the page shows it."""
    section = (ROOT / "docs" / "lab-guide.md").read_text().split("## Add a car to the fleet")[1]
    block = section.split("```toml\n")[1].split("```")[0]
    return "\n" + textwrap.dedent(block)


CAR_5 = lab_guide_car_5()


def keys(config, out, *argv):
    return subprocess.run([sys.executable, "-m", "trustfg", "keys", "--config", str(config), "--out", str(out),
                           "--owner", ME, *argv], capture_output=True, text=True, timeout=120)


def snapshot(out: Path) -> dict[str, tuple[bytes, int, int]]:
    """Every file under ``out``: its bytes, modification time (ns) and mode."""
    return {str(p.relative_to(out)): (p.read_bytes(), p.stat().st_mtime_ns, p.stat().st_mode & 0o777)
            for p in sorted(out.rglob("*")) if p.is_file()}


def lab_copy(tmp_path) -> Path:
    config = tmp_path / "fleet.toml"
    config.write_text((ROOT / "deploy" / "lab" / "fleet.toml").read_text())
    return config


def assert_member(out: Path, car: int) -> None:
    """Car ``car``'s files: a link key the car process reads, a TLS key and a certificate
    of common name carN from the fleet's CA; secrets 0600, certificates 0644."""
    link, key, cert = out / f"car{car}.link.key", out / "tls" / f"car{car}.tls.key", out / "tls" / f"car{car}.tls.crt"
    assert len(parse_key(link.read_text(), str(link))) == 32
    assert key.read_text().startswith("-----BEGIN PRIVATE KEY-----")
    assert certificates.problem(cert, key, out / "tls" / "ca.tls.crt") is None
    subject = subprocess.run(["openssl", "x509", "-in", str(cert), "-noout", "-subject"], capture_output=True,
                             text=True, check=True).stdout
    assert subject.strip().endswith(f"CN = car{car}")
    assert [p.stat().st_mode & 0o777 for p in (link, key, cert)] == [0o600, 0o600, 0o644]
    assert {p.stat().st_uid for p in (link, key, cert)} == {os.geteuid()}


def test_a_fleet_gets_every_file_and_where_it_goes(tmp_path):
    out = tmp_path / "keys"
    done = keys(lab_copy(tmp_path), out)
    assert done.returncode == 0, done.stderr
    for car in (1, 2, 3, 4):
        assert_member(out, car)
    assert (out / "tls" / "ca.tls.key").stat().st_mode & 0o777 == 0o600
    assert certificates.problem(out / "tls" / "operator.tls.crt", out / "tls" / "operator.tls.key",
                                out / "tls" / "ca.tls.crt") is None
    assert not [p for p in out.rglob("*") if p.name.startswith(".")]  # nothing half-written left behind
    said = done.stdout
    assert said.count("  made ") == 4 + 2 + 2 + 8 and "kept" not in said
    assert "car 3's computer (10.0.0.103)" in said
    assert "sudo install -D -m 600 -o trustfg -g trustfg car3.link.key /etc/trustfg/car3.link.key" in said
    assert "sudo install -D -m 600 -o trustfg -g trustfg car3.tls.key /etc/trustfg/tls/car3.tls.key" in said
    assert f"car 3's firmware: the 32 bytes written in {out / 'car3.link.key'}" in said
    laptop = said.split("the operator's laptop")[1]
    assert all(f'-o "$USER" car{car}.link.key /etc/trustfg/car{car}.link.key' in laptop for car in (1, 2, 3, 4))
    assert "operator.tls.key" in laptop and "car3.tls.key" not in laptop


def test_adding_a_car_makes_its_files_alone_and_keeps_the_ca_and_every_other_file(tmp_path):
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    assert keys(config, out).returncode == 0
    before = snapshot(out)
    # the lab guide's steps: a [[cars]] entry, its computer in [bus] connect, trustfg keys --cars 5
    assert "trustfg keys --config fleet.toml --owner \"$USER\" --cars 5" in (ROOT / "docs" / "lab-guide.md").read_text()
    text = config.read_text().replace('"udp/10.0.0.104:7448?rel=0"]',
                                      '"udp/10.0.0.104:7448?rel=0",\n           "tcp/10.0.0.105:7447", '
                                      '"udp/10.0.0.105:7448?rel=0"]')
    config.write_text(text + CAR_5)
    fleet = load_scenario(config)
    assert [c.id for c in fleet.cars] == [1, 2, 3, 4, 5] and "tcp/10.0.0.105:7447" in fleet.bus.connect
    checked = subprocess.run([sys.executable, "-m", "trustfg", "scenario", "check", str(config)], capture_output=True,
                             text=True, timeout=60)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    done = keys(config, out, "--cars", "5")
    assert done.returncode == 0, done.stderr
    after = snapshot(out)
    assert {name: after[name] for name in before} == before  # the CA and cars 1-4: same bytes, same times
    assert sorted(set(after) - set(before)) == ["car5.link.key", "tls/car5.tls.crt", "tls/car5.tls.key"]
    assert_member(out, 5)
    assert "car 5's computer (10.0.0.105)" in done.stdout and "car 4's computer" not in done.stdout
    assert "kept      the fleet's CA certificate" in done.stdout
    # every machine's Zenoh config names car 5 now
    tls = secure_config(fleet.fleet, [1, 2, 3, 4, 5], out / "tls", "car5")["transport"]["link"]["tls"]
    assert tls["listen_certificate"] == str((out / "tls" / "car5.tls.crt").resolve())
    # and the whole fleet once more: nothing changes at all
    again = keys(config, out)
    assert again.returncode == 0 and "made" not in again.stdout and "replaced" not in again.stdout
    assert snapshot(out) == after


def test_rotate_replaces_the_named_cars_files_alone_and_says_which(tmp_path):
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    assert keys(config, out).returncode == 0
    before = snapshot(out)
    done = keys(config, out, "--cars", "2", "--rotate")
    assert done.returncode == 0, done.stderr
    after = snapshot(out)
    changed = sorted(name for name in after if after[name][0] != before[name][0])
    assert changed == ["car2.link.key", "tls/car2.tls.crt", "tls/car2.tls.key"]
    said = [line for line in done.stdout.splitlines() if line.startswith("changed: ")]
    assert len(said) == 1 and all(str(out / name) in said[0] for name in changed)
    assert_member(out, 2)
    assert {name: after[name] for name in after if name not in changed} == \
        {name: before[name] for name in before if name not in changed}


def test_what_it_will_not_overwrite_or_cannot_sign_is_refused_in_one_line(tmp_path):
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    assert keys(config, out).returncode == 0
    (out / "car3.link.key").write_text("not a key\n")
    before = snapshot(out)
    done = keys(config, out)
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "car3.link.key: a car-link key is 64 hexadecimal digits; --rotate --cars 3 makes a new one" in done.stderr
    assert snapshot(out) == before and done.stdout == ""
    assert keys(config, out, "--cars", "3", "--rotate").returncode == 0
    # the CA's key kept offline: the fleet as it is needs nothing signed; a new car does
    (out / "tls" / "ca.tls.key").unlink()
    assert keys(config, out).returncode == 0
    config.write_text(config.read_text() + CAR_5)
    done = keys(config, out, "--cars", "5")
    assert done.returncode == 2 and "the CA's key" in done.stderr and "ca.tls.key is not here" in done.stderr
    assert not (out / "car5.link.key").exists() and not (out / "tls" / "car5.tls.crt").exists()


def test_another_cas_certificate_is_refused_until_rotated(tmp_path):
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    assert keys(config, out, "--cars", "1").returncode == 0
    assert keys(config, tmp_path / "other", "--cars", "1").returncode == 0
    for name in ("ca.tls.crt", "ca.tls.key"):
        (out / "tls" / name).write_bytes((tmp_path / "other" / "tls" / name).read_bytes())
    done = keys(config, out, "--cars", "1")
    assert done.returncode == 2 and "car1.tls.crt: it does not verify against ca.tls.crt: signed by another CA" \
        in done.stderr
    assert keys(config, out, "--rotate").returncode == 0
    assert_member(out, 1)


def test_the_owner_is_named_as_root_and_nobody_else_is_given_files_without_root():
    with pytest.raises(KeysError, match="--owner USER"):
        owner_of(None, euid=0)
    nobody = pwd.getpwnam("nobody")
    assert owner_of("nobody", euid=0).uid == nobody.pw_uid and owner_of("nobody", euid=0).chown
    with pytest.raises(KeysError, match="only root can give files to another user"):
        owner_of("root", euid=nobody.pw_uid)
    mine = owner_of(None, euid=nobody.pw_uid)
    assert (mine.uid, mine.user, mine.chown) == (nobody.pw_uid, "nobody", False)
    with pytest.raises(KeysError, match="no such user"):
        owner_of("no-such-user-here", euid=0)


def test_a_file_of_another_user_is_refused_without_root(tmp_path):
    """A key written by root earlier is not silently kept by a user who cannot read it."""
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    assert keys(config, out, "--cars", "1").returncode == 0
    stranger = os.geteuid() + 1
    plan = survey(list(load_scenario(config).cars[:1]), out, False, False, euid=stranger)
    assert any(f"{out / 'car1.link.key'} belongs to {ME}, not to you" in p for p in plan.problems)


@pytest.mark.skipif(os.geteuid() != 0, reason="giving files to another user needs root")
def test_as_root_the_files_go_to_the_owner_named(tmp_path):
    config, out = lab_copy(tmp_path), tmp_path / "keys"
    done = subprocess.run([sys.executable, "-m", "trustfg", "keys", "--config", str(config), "--out", str(out),
                           "--owner", "nobody", "--cars", "1"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    nobody = pwd.getpwnam("nobody")
    assert {(p.stat().st_uid, p.stat().st_gid) for p in out.rglob("*") if p.is_file()} == \
        {(nobody.pw_uid, nobody.pw_gid)}
    os.chown(out / "car1.link.key", 0, 0)  # the first day's mistake: a key of root's alone
    mended = subprocess.run([sys.executable, "-m", "trustfg", "keys", "--config", str(config), "--out", str(out),
                             "--owner", "nobody", "--cars", "1"], capture_output=True, text=True, timeout=120)
    assert mended.returncode == 0 and "(owner nobody set)" in mended.stdout
    assert (out / "car1.link.key").stat().st_uid == nobody.pw_uid
