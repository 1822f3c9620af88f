"""``trustfg keys --config FILE``: a fleet's keys and certificates, made once, and where each goes.

For every car of the fleet (or those of ``--cars``) it makes, in ``--out``, the car-link
key ``carN.link.key`` (bridge.carlink.keys) and, in ``OUT/tls``, the car's TLS key and
certificate ``carN.tls.key`` and ``carN.tls.crt``; the operator's ``operator.tls.*`` too,
all signed by the fleet's CA (``ca.tls.crt``, ``ca.tls.key``: fleet.bus.certificates).
The CA is made once and reused, so adding a car issues that car's files alone. An
existing key is never overwritten: ``--rotate`` makes the named cars' files anew (every
car's and the operator's without ``--cars``; never the CA's) and says which changed.
Secrets are mode 0600 and certificates 0644, owned by ``--owner`` (given as root; without
root the files are yours, and another owner is refused). Then it prints what to copy to
which machine: each car's computer, each car's firmware, the operator's laptop.
"""

from __future__ import annotations

import grp
import os
import pwd
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ...agent.config import CarConfig, ConfigError, Scenario
from ...agent.scenario_files import load_scenario
from ...bridge.carlink.keys import key_file_name, new_key, parse_key, write_key_file
from ..bus import certificates
from ..bus.certificates import CA, CertificateError, cert_name, key_name
from ..bus.security import CERTS_AT
from ..program import command_parser, configured
from .estop_direct import named

DEFAULT_OUT = Path(CERTS_AT).parent
"""/etc/trustfg: where the lab's configs read the link keys, and the TLS files under tls/."""

SECRET, PUBLIC = 0o600, 0o644
OPERATOR = "operator"


class KeysError(Exception):
    """What ``trustfg keys`` refuses to do, and why (one line for the user)."""


@dataclass(frozen=True)
class Owner:
    uid: int
    gid: int
    user: str
    chown: bool
    """Whether files are given to this owner (as root, or another group of one's own)."""


@dataclass(frozen=True)
class Step:
    """One file's fate: ``make`` (new), ``keep``, ``replace`` (--rotate) or ``issue`` (a
    certificate for a key that is already there)."""

    action: str
    path: Path
    what: str
    mode: int
    settle: bool = True
    """Bring it to its mode and owner: a file of the members named (with ``--cars``, the
    CA's and the operator's files are only read, and left as they are)."""


@dataclass
class Plan:
    out: Path
    link: list[Step] = field(default_factory=list)
    ca: list[Step] = field(default_factory=list)
    members: dict[str, list[Step]] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def steps(self) -> list[Step]:
        return [*self.link, *self.ca, *(s for steps in self.members.values() for s in steps)]


def owner_of(spec: str | None, euid: int) -> Owner:
    """Who the files belong to: ``USER[:GROUP]``, or whoever runs the command. As root an
    owner must be named (files of root's alone are what a car service cannot read)."""
    if spec is None:
        if euid == 0:
            raise KeysError("run as root, the files would be root's alone: --owner USER[:GROUP] names who reads "
                            "them (on the operator's laptop the operator, e.g. --owner \"$SUDO_USER\")")
        entry = pwd.getpwuid(euid)
        return Owner(euid, entry.pw_gid, entry.pw_name, chown=False)
    user, _, group = spec.partition(":")
    try:
        entry = pwd.getpwnam(user)
        gid = grp.getgrnam(group).gr_gid if group else entry.pw_gid
    except KeyError:
        raise KeysError(f"--owner {spec}: no such user or group on this machine") from None
    if euid != 0 and entry.pw_uid != euid:
        raise KeysError(f"--owner {spec}: only root can give files to another user (run it with sudo, or "
                        f"leave --owner out to keep them yours)")
    return Owner(entry.pw_uid, gid, user, chown=euid == 0 or gid != entry.pw_gid)


def survey(cars: list[CarConfig], out: Path, rotate: bool, every: bool, euid: int) -> Plan:
    """What would be made, kept or replaced, and every reason to refuse -- before any
    file is written. ``every``: the whole fleet is named (then --rotate includes the
    operator's files)."""
    plan = Plan(out)
    tls = out / "tls"
    _check_access(cars, out, every, euid, plan)
    if plan.problems:  # files it may not read or change: nothing more is looked at
        return plan
    for car in cars:
        if car.link_version == 2:
            plan.link.append(_link_step(out / key_file_name(car.id), car.id, rotate, plan))
    plan.members[OPERATOR] = _member_steps(tls, OPERATOR, rotate and every, plan, "--rotate")
    for car in cars:
        plan.members[f"car{car.id}"] = _member_steps(tls, f"car{car.id}", rotate, plan, f"--rotate --cars {car.id}")
    plan.ca = _ca_steps(tls, any(s.action != "keep" for steps in plan.members.values() for s in steps), plan)
    if not every:  # the CA's and the operator's files, when only consulted, stay as they are
        plan.ca = [_consulted(s) for s in plan.ca]
        plan.members[OPERATOR] = [_consulted(s) for s in plan.members[OPERATOR]]
    return plan


def _check_access(cars: list[CarConfig], out: Path, every: bool, euid: int, plan: Plan) -> None:
    """Without root: every file there that this run would read must be readable, and every
    file of the members named must be one's own (its mode is set); the folders writable."""
    tls = out / "tls"
    ours = [out / key_file_name(c.id) for c in cars]
    ours += [tls / name(f"car{c.id}") for c in cars for name in (key_name, cert_name)]
    shared = [tls / name(who) for who in (CA, OPERATOR) for name in (key_name, cert_name)]
    if euid != 0:
        for path in (p for p in ours + shared if p.exists()):
            owner = path.stat().st_uid
            if owner != euid and (path in ours or every or not os.access(path, os.R_OK)):
                plan.problems.append(f"{path} belongs to {_user(owner)}, not to you (run it as root with --owner)")
    for folder in (out, tls):
        writable = _existing(folder)
        if not os.access(writable, os.W_OK):
            plan.problems.append(f"cannot write in {writable} (run it as root with --owner, or choose --out)")


def _consulted(step: Step) -> Step:
    return step if step.action != "keep" else Step(step.action, step.path, step.what, step.mode, settle=False)


def _link_step(path: Path, car_id: int, rotate: bool, plan: Plan) -> Step:
    what = f"car {car_id}'s link key"
    if not path.exists():
        return Step("make", path, what, SECRET)
    if rotate:
        return Step("replace", path, what, SECRET)
    try:
        parse_key(path.read_text(), str(path))
    except (ConfigError, OSError, UnicodeDecodeError) as exc:
        plan.problems.append(f"{exc}; --rotate --cars {car_id} makes a new one")
    return Step("keep", path, what, SECRET)


def _member_steps(tls: Path, identity: str, renew: bool, plan: Plan, rotate_flags: str) -> list[Step]:
    key, cert = tls / key_name(identity), tls / cert_name(identity)
    whose = "the operator's" if identity == OPERATOR else f"car {identity.removeprefix('car')}'s"
    key_what, cert_what = f"{whose} TLS key", f"{whose} TLS certificate"
    if renew or not key.exists():
        action = "replace" if key.exists() or cert.exists() else "make"
        return [Step(action, key, key_what, SECRET), Step(action, cert, cert_what, PUBLIC)]
    if not cert.exists():
        return [Step("keep", key, key_what, SECRET), Step("issue", cert, cert_what, PUBLIC)]
    ca_cert = tls / cert_name(CA)
    why = certificates.problem(cert, key, ca_cert) if ca_cert.exists() else f"there is no {ca_cert.name} to check it"
    if why:
        plan.problems.append(f"{cert}: {why}; {rotate_flags} issues it anew")
    return [Step("keep", key, key_what, SECRET), Step("keep", cert, cert_what, PUBLIC)]


def _ca_steps(tls: Path, signing: bool, plan: Plan) -> list[Step]:
    cert, key = tls / cert_name(CA), tls / key_name(CA)
    steps = [Step("keep", cert, "the fleet's CA certificate", PUBLIC), Step("keep", key, "the CA's key", SECRET)]
    if not cert.exists() and not key.exists():
        return [Step("make", s.path, s.what, s.mode) for s in steps]
    if not cert.exists():
        plan.problems.append(f"{key} is there without {cert.name}: move it away to make a new CA")
    elif not key.exists():
        if signing:
            plan.problems.append(f"the CA's key {key} is not here (kept offline?): put it back to issue the "
                                 f"certificates")
        return steps[:1]
    elif not certificates.ca_matches(cert, key):
        plan.problems.append(f"{key} is not the key of {cert}")
    return steps


def carry_out(plan: Plan, owner: Owner) -> list[str]:
    """Write what the plan makes, set modes and owners; the lines saying what happened."""
    plan.out.mkdir(parents=True, exist_ok=True)
    (plan.out / "tls").mkdir(exist_ok=True)
    ca_cert, ca_key = plan.out / "tls" / cert_name(CA), plan.out / "tls" / key_name(CA)
    if plan.ca and plan.ca[0].action == "make":
        with tempfile.TemporaryDirectory() as tmp:
            key = _stage(Path(tmp), certificates.new_key())
            cert = certificates.new_ca(key)
            _write(ca_key, key.read_bytes(), SECRET, owner)
            _write(ca_cert, cert, PUBLIC, owner)
    for identity, (key_step, cert_step) in plan.members.items():
        if key_step.action in ("make", "replace"):
            with tempfile.TemporaryDirectory() as tmp:
                key = _stage(Path(tmp), certificates.new_key())
                cert = certificates.issue(identity, key, ca_cert, ca_key)
                _write(key_step.path, key.read_bytes(), SECRET, owner)
                _write(cert_step.path, cert, PUBLIC, owner)
        elif cert_step.action == "issue":
            _write(cert_step.path, certificates.issue(identity, key_step.path, ca_cert, ca_key), PUBLIC, owner)
    for step in plan.link:
        if step.action != "keep":
            with tempfile.TemporaryDirectory(dir=step.path.parent) as tmp:
                staged = write_key_file(Path(tmp) / step.path.name, new_key())
                _give(staged, owner)
                staged.replace(step.path)
    said = {"make": "made", "keep": "kept", "replace": "replaced", "issue": "issued"}
    lines = []
    for step in plan.steps:
        settled = _settle(step.path, step.mode, owner) if step.settle else ""
        lines.append(f"  {said[step.action]:<9} {step.what:<31} {step.path}{settled}")
    return lines


def _stage(folder: Path, key: bytes) -> Path:
    path = folder / "key.pem"
    _write(path, key, SECRET, None)
    return path


def _write(path: Path, data: bytes, mode: int, owner: Owner | None) -> None:
    """Write ``data`` to a new file beside ``path`` with ``mode`` and ``owner``, then move
    it over ``path``: nobody ever reads a half-written or wrongly owned key."""
    with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", delete=False) as f:
        staged = Path(f.name)
    try:
        staged.write_bytes(data)  # made 0600 (mkstemp)
        os.chmod(staged, mode)
        if owner is not None:
            _give(staged, owner)
        staged.replace(path)
    except BaseException:
        staged.unlink(missing_ok=True)
        raise


def _give(path: Path, owner: Owner) -> None:
    if owner.chown:
        os.chown(path, owner.uid, owner.gid)


def _settle(path: Path, mode: int, owner: Owner) -> str:
    """Bring a file to its mode and owner; what had to change (empty: nothing)."""
    done = []
    stat = path.stat()
    if stat.st_mode & 0o777 != mode:
        os.chmod(path, mode)
        done.append(f"mode {mode:04o}")
    if owner.chown and (stat.st_uid, stat.st_gid) != (owner.uid, owner.gid):
        os.chown(path, owner.uid, owner.gid)
        done.append(f"owner {owner.user}")
    return f" ({', '.join(done)} set)" if done else ""


def _existing(folder: Path) -> Path:
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    return folder


def _user(uid: int) -> str:
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def computer(car: CarConfig) -> str:
    """Car ``car``'s computer, as a person finds it: its address from ``cars[].listen``."""
    hosts = {e.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]") for e in car.listen}
    return f"car {car.id}'s computer" + (f" ({', '.join(sorted(hosts))})" if hosts else "")


def link_destination(car: CarConfig) -> Path:
    """Where the config reads car ``car``'s link key, on the car's computer and the laptop."""
    return Path(car.link_key_file) if car.link_key_file else DEFAULT_OUT / key_file_name(car.id)


def copy_plan(fleet: Scenario, cars: list[CarConfig], out: Path, car_user: str) -> list[str]:
    """Which file goes to which machine, as the commands that install it there."""
    tls, at = out / "tls", Path(CERTS_AT)
    service, operator = f"-o {car_user} -g {car_user} ", '-o "$USER" '

    def install(source: Path, destination: Path, mode: int, owner: str = "") -> str:
        if source.resolve() == destination.resolve():
            return f"    {destination}: in place"
        return f"    sudo install -D -m {mode:o} {owner}{source.name} {destination}"

    lines = ["", "where each file goes (copy it to that machine, then install it there as shown):"]
    for car in cars:
        identity = f"car{car.id}"
        lines.append(f"  {computer(car)}, for the car service's user {car_user}:")
        if car.link_version == 2:
            lines.append(install(out / key_file_name(car.id), link_destination(car), SECRET, service))
        lines += [install(tls / key_name(identity), at / key_name(identity), SECRET, service),
                  install(tls / cert_name(identity), at / cert_name(identity), PUBLIC),
                  install(tls / cert_name(CA), at / cert_name(CA), PUBLIC)]
        if car.link_version == 2:
            lines.append(f"  car {car.id}'s firmware: the 32 bytes written in {out / key_file_name(car.id)}")
        if car.link_key:
            lines.append(f"  (cars[id={car.id}] gives its key inline, link_key: name its file in link_key_file)")
    lines.append("  the operator's laptop, for the operator's account:")
    lines += [install(out / key_file_name(car.id), link_destination(car), SECRET, operator)
              for car in cars if car.link_version == 2]
    lines += [install(tls / key_name(OPERATOR), at / key_name(OPERATOR), SECRET, operator),
              install(tls / cert_name(OPERATOR), at / cert_name(OPERATOR), PUBLIC),
              install(tls / cert_name(CA), at / cert_name(CA), PUBLIC)]
    ids = " ".join(str(c.id) for c in fleet.cars)
    lines += [f"  keep {tls / key_name(CA)} on this machine alone: only adding a car needs it.",
              "the tls/ files serve a secure fleet ([bus] zenoh_config); its Zenoh config per machine:",
              f"  trustfg secure-config --fleet {fleet.fleet} --cars {ids} --certs {tls} --identity carN|operator "
              f"--out IDENTITY.json5"]
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg keys", __doc__, whole=True)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="the folder to make the files in")
    parser.add_argument("--owner", default=None,
                        help="USER[:GROUP] the files belong to (as root: required; default: you)")
    parser.add_argument("--cars", type=int, nargs="+", default=[], help="only these cars (default: every car)")
    parser.add_argument("--rotate", action="store_true",
                        help="make the named cars' keys and certificates anew (without --cars: the operator's too)")
    parser.add_argument("--car-user", default="trustfg",
                        help="the account the car services run as (install.sh --user), for the printed commands")
    args = parser.parse_args(argv)
    fleet = configured("trustfg keys", lambda: load_scenario(args.config))
    try:
        ids = named(fleet, args.cars)
    except ValueError as exc:
        parser.error(str(exc))
    cars = [car for car in fleet.cars if car.id in ids]
    try:
        owner = owner_of(args.owner, os.geteuid())
        plan = survey(cars, args.out, args.rotate, not args.cars, os.geteuid())
        if plan.problems:
            raise KeysError("; ".join(plan.problems))
        done = carry_out(plan, owner)
    except (KeysError, CertificateError, OSError) as exc:
        print(f"trustfg keys: {exc}", file=sys.stderr)
        return 2
    print(f"trustfg keys: fleet {fleet.fleet}, cars {' '.join(map(str, ids))}, in {args.out} (owner {owner.user})")
    print("\n".join(done))
    changed = [str(step.path) for step in plan.steps if step.action == "replace"]
    if changed:
        print(f"changed: {' '.join(changed)} -- install them again where they go (below; a new link key into its "
              f"car's firmware too), then restart those cars' services")
    print("\n".join(copy_plan(fleet, cars, args.out, args.car_user)))
    return 0
