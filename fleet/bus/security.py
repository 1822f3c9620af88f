"""The fleet bus secured with Zenoh's own features: mutual TLS and access control.

    trustfg secure-config --fleet F --cars 1 2 3 4 --certs DIR --identity car1 --out car1.json5

writes the JSON5 to name in ``[bus] zenoh_config`` (endpoints must then be ``tls/...``) for
one identity (a certificate's common name: ``carN`` for car N, ``operator`` for go,
dashboard and record). Without a certificate of the fleet's CA a session cannot connect
at all. Access control, default deny, is enforced by every receiver on what each
authenticated peer sends: car N may put only under ``trustfg/F/N/**``, only the operator
may put the start, the stop and the heartbeat, and everyone may read. It checks that DIR
holds the identity's files and writes the paths where they will be on the machine that
uses them (``--certs-at``: docs/lab-guide.md).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from ..program import command_parser
from . import key_exprs
from .certificates import CA, cert_name, key_name

ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"]
READ = ["declare_subscriber", "declare_liveliness_subscriber", "query", "liveliness_query"]
WRITE = ["put", "delete", "declare_queryable", "reply"]


CERTS_AT = "/etc/trustfg/tls"
"""Where docs/lab-guide.md installs each machine's certificates."""


def identities(cars: list[int]) -> list[str]:
    """The fleet's identities (certificate common names): the operator's and carN's."""
    return ["operator", *(f"car{car}" for car in cars)]


def certificate_names(certs: Path, identity: str, certs_at: str | Path | None = None) -> dict[str, str]:
    """Paths of the CA certificate and of this identity's key and certificate: checked in
    ``certs``, written as under ``certs_at`` (default: ``certs`` itself, resolved)."""
    names = {"ca": cert_name(CA), "key": key_name(identity), "cert": cert_name(identity)}
    missing = [str(certs / name) for name in names.values() if not (certs / name).exists()]
    if missing:
        raise FileNotFoundError(f"missing TLS files: {', '.join(missing)} (trustfg keys makes them)")
    folder = Path(certs_at) if certs_at is not None else certs.resolve()
    return {k: str(folder / name) for k, name in names.items()}


def access_control(fleet: str, cars: list[int]) -> dict:
    everything = key_exprs.fleet_tree(fleet)
    rules = [
        {"id": "send-anything", "permission": "allow", "flows": ["egress"], "messages": ALL_MESSAGES,
         "key_exprs": ["**", "**/@adv/**"]},
        {"id": "read-the-fleet", "permission": "allow", "flows": ["ingress"], "messages": READ,
         "key_exprs": everything},
        # Advanced subscribers announce themselves with tokens under @adv of what they read.
        {"id": "subscriber-tokens", "permission": "allow", "flows": ["ingress"], "messages": ["liveliness_token"],
         "key_exprs": everything[1:]},
        {"id": "operator-keys", "permission": "allow", "flows": ["ingress"], "messages": WRITE + ["liveliness_token"],
         "key_exprs": [k for name in key_exprs.OPERATOR for k in key_exprs.fleet_key_tree(fleet, name)]},
    ]
    subjects = [{"id": "operator", "cert_common_names": ["operator"]}]
    policies = [{"id": "operator", "rules": ["send-anything", "read-the-fleet", "subscriber-tokens", "operator-keys"],
                 "subjects": ["operator"]}]
    for car in cars:
        rules.append({"id": f"car{car}-own-keys", "permission": "allow", "flows": ["ingress"],
                      "messages": WRITE + ["liveliness_token"], "key_exprs": key_exprs.car_tree(fleet, car)})
        subjects.append({"id": f"car{car}", "cert_common_names": [f"car{car}"]})
        policies.append({"id": f"car{car}", "rules": ["send-anything", "read-the-fleet", "subscriber-tokens",
                                                       f"car{car}-own-keys"], "subjects": [f"car{car}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def secure_config(fleet: str, cars: list[int], certs: Path, identity: str,
                  certs_at: str | Path | None = None) -> dict:
    """The Zenoh config (as a dict) for one process: its TLS identity and the fleet's ACL.
    ValueError for an identity that is not the fleet's."""
    if identity not in identities(cars):
        raise ValueError(f"identity {identity!r} is not in this fleet (expected one of {', '.join(identities(cars))})")
    paths = certificate_names(certs, identity, certs_at)
    tls = {"root_ca_certificate": paths["ca"], "listen_private_key": paths["key"], "listen_certificate": paths["cert"],
           "connect_private_key": paths["key"], "connect_certificate": paths["cert"], "enable_mtls": True,
           "verify_name_on_connect": False}
    return {"transport": {"link": {"tls": tls}}, "access_control": access_control(fleet, cars)}


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg secure-config", __doc__)
    parser.add_argument("--fleet", required=True, help="the fleet's name (its config's `fleet`)")
    parser.add_argument("--cars", type=int, nargs="+", required=True, help="the fleet's car ids")
    parser.add_argument("--certs", type=Path, required=True, help="the TLS folder trustfg keys made (its OUT/tls; read here)")
    parser.add_argument("--certs-at", default=CERTS_AT,
                        help="where the certificates will be on the machine that uses this config")
    parser.add_argument("--identity", required=True, help="carN (N one of --cars) or operator")
    parser.add_argument("--out", type=Path, required=True, help="the JSON5 file to write")
    args = parser.parse_args(argv)
    try:
        config = secure_config(args.fleet, args.cars, args.certs, args.identity, args.certs_at)
    except (FileNotFoundError, ValueError) as exc:
        print(f"trustfg secure-config: {exc}", file=sys.stderr)
        return 2
    args.out.write_text(json.dumps(config, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0
